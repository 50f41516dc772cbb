"""PRINTEPS gateway: a Drools-backed rules server with a Python gateway for service robots.

The package is organised one module per concept:

- ``gateway.jvm``        the one JVM per process (JPype), its classpath and the Java helpers
- ``gateway.engine``     rule sets, compilation, versions/hot deploy, firing, sessions
- ``gateway.rdf``        messages -> RDF triples
- ``gateway.stream``     C-SPARQL continuous queries over RDF streams
- ``gateway.ontology``   the teahouse ontology and SWRL reasoning (owlready2 + Pellet)
- ``gateway.store``      the Information State (MongoDB through pymongo)
- ``gateway.ros``        the ROS 2 node, simulators and action dispatch
- ``gateway.workflow``   workflows: the teahouse business processes
- ``gateway.api``        the REST gateway (FastAPI) and the workbench
- ``gateway.cli``        the ``printeps`` command
"""

__version__ = "0.1.0"
