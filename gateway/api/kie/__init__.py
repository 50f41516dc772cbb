"""KIE Server compatibility: the batch JSON (:mod:`.batch`) and the server/container resources
(:mod:`.containers`) of KIE Server 7.x, for ``gateway.api.routes.kie_server``."""
