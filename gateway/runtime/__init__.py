"""The services a running gateway process runs beside its engines, wired by ``gateway.app``.

- ``gateway.runtime.jobs``      background builds (deploys, validations) and their progress records
- ``gateway.runtime.progress``  a build's progress drawn on the terminal (the CLI)
- ``gateway.runtime.follower``  the thread that follows the catalog's change log (every process, every change)
- ``gateway.runtime.live``      the live feed of what this process sees happen
- ``gateway.runtime.actions``   a decision's actions routed to what performs them
- ``gateway.runtime.transfer``  the Information State to and from a folder (``printeps export``/``import``)

They sit above the engines, the stream, the workflows and the store (they use them) and below the
interfaces (REST, ROS) and the composition root (see docs/architecture.md).
"""
