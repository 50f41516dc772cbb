"""What every layer of the gateway stands on: the process's one JVM and the versioned catalog.

- ``gateway.base.jvm``       the one JVM per process (JPype), its classpath and the Java helpers
- ``gateway.base.jvm_cache`` the JVM's AOT class cache: which file, when a start uses it
- ``gateway.base.versions``  the catalog of versioned things an author changes, and its change log

Nothing here imports another ``gateway`` package but ``gateway.config`` (see docs/architecture.md).
"""
