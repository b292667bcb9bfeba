"""What the service can do: one module a capability, each with its params model, the parts it
reads, its use-case, its answer model, its other forms and its table row (``ROWS``).

This list of modules is the registry: the routes (:mod:`service.routes`), the OpenAPI
document (:mod:`service.document`), its examples, the command line and the batch are derived
from their rows. What several capabilities share lives beside them: the region every mesh
route starts from (:mod:`.region`), drawn zones (:mod:`.drawn`), units (:mod:`.units`), the
field types (:mod:`.fields`), typed inputs (:mod:`.inputs`), the rows (:mod:`.rows`) and the
context a use-case runs in (:mod:`.context`).
"""

from __future__ import annotations

from . import (
    compare,
    fit,
    flatten,
    locate,
    measure,
    plan,
    points,
    register,
    sites,
    strands,
    transfer,
    validate,
)
from .rows import Capability, JsonCapability, MeshCapability

#: The capability modules, in the order of the API's reference.
MODULES = (
    flatten,
    validate,
    fit,
    locate,
    measure,
    plan,
    sites,
    strands,
    register,
    compare,
    transfer,
    points,
)

#: Every row of the table.
CAPABILITIES: tuple[Capability, ...] = tuple(row for module in MODULES for row in module.ROWS)
MESH_CAPABILITIES = tuple(c for c in CAPABILITIES if isinstance(c, MeshCapability))
JSON_CAPABILITIES = tuple(c for c in CAPABILITIES if isinstance(c, JsonCapability))

#: The mesh routes by command-line command.
MESH_COMMANDS = {capability.command: capability for capability in MESH_CAPABILITIES}

__all__ = [
    "CAPABILITIES",
    "JSON_CAPABILITIES",
    "MESH_CAPABILITIES",
    "MESH_COMMANDS",
    "MODULES",
    "Capability",
    "JsonCapability",
    "MeshCapability",
]
