"""A local service for offline-programming tools that are not Python (``olp-fix serve``).

JSON-RPC 2.0, one message per line on a pipe (:mod:`.stdio`) or the body of ``POST /rpc``
over HTTP with an OpenAPI description (:mod:`.http`, :mod:`.openapi`); the methods
``compensate_poses`` (:mod:`.poses`) and ``compensate_program`` (:mod:`.program`) on
calibrations kept in memory by content hash (:mod:`.calls`).
"""

from .calls import Service, ServiceError

__all__ = ["Service", "ServiceError"]
