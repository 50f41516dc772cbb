"""PRINTEPS gateway: a Drools-backed rules server with a Python gateway for service robots.

The package is organised one module per concept:

- ``gateway.config``      settings (YAML + environment)
- ``gateway.base``        the one JVM per process (``jvm``) and the versioned catalog (``versions``)
- ``gateway.rdf``         messages -> RDF triples
- ``gateway.store``       the Information State (MongoDB through pymongo)
- ``gateway.engine``      rule sets, compilation, versions/hot deploy, firing, sessions
- ``gateway.stream``      C-SPARQL continuous queries over RDF streams
- ``gateway.ontology``    the teahouse ontology and SWRL reasoning (owlready2 + Pellet)
- ``gateway.dialogue``    spoken orders: grammar, menu, speech
- ``gateway.workflow``    workflows: the teahouse business processes
- ``gateway.runtime``     a process's services: build jobs, change follower, live feed, action router, transfer
- ``gateway.api``, ``gateway.workbench``, ``gateway.ros``   the REST gateway, the workbench, the ROS 2 node
- ``gateway.app``         the composition root: builds one gateway from the above
- ``gateway.cli``, ``gateway.serve``, ``gateway.demo``, ``gateway.worker``, ``gateway.ros_launch``   entry points

A module imports only from its own line and the lines above it (checked by ``tests/meta/test_layers.py``; docs/architecture.md draws it).
"""

__version__ = "0.1.0"
