"""The layout of the unknown vector of an identification: which group sits where.

x = [device registration (6) | free geometric parameters | tool points (3 each) |
tool rotations (3 each) | effect parameters (each effect's, in order)].

The registration is ``device_T_base = (R0 Exp(phi), t0 + R0 rho)`` with ``x[translation] =
rho`` (m) and ``x[rotation] = phi`` (rad); a tool point is (x, y, z) in the flange frame, m;
a tool rotation is the rotation vector r of ``R_tool0 Exp(r)``, rad. Every index into x is
taken from an :class:`UnknownLayout`; no other module computes offsets.
"""

from __future__ import annotations

from dataclasses import dataclass

REGISTRATION_NAMES = ("base.tx", "base.ty", "base.tz", "base.rx", "base.ry", "base.rz")


@dataclass(frozen=True)
class UnknownLayout:
    """Named slices of the unknown vector (see the module docstring); build it with
    :meth:`build`.

    ``geometry_names``: the free model parameters (``j3.beta``...); ``tool_names``: the
    measured tool points; ``rotated_tools``: the tools whose rotation is an unknown (those
    with orientation rows); ``effect_names``: per effect, its unknowns' names
    (``joint_compliance j2.c``...)."""

    geometry_names: tuple[str, ...]
    tool_names: tuple[str, ...]
    rotated_tools: tuple[str, ...]
    effect_names: tuple[tuple[str, ...], ...]
    registration: slice
    registration_translation: slice
    registration_rotation: slice
    geometry: slice
    tool_points: slice
    tool_rotations: slice
    effect_block: slice
    effects: tuple[slice, ...]
    size: int

    @classmethod
    def build(cls, geometry_names, tool_names, rotated_tools=(), effect_names=()
              ) -> "UnknownLayout":
        """The layout for these groups, in the order of the module docstring."""
        geometry_names, tool_names = tuple(geometry_names), tuple(tool_names)
        rotated_tools = tuple(rotated_tools)
        effect_names = tuple(tuple(names) for names in effect_names)
        geometry = slice(6, 6 + len(geometry_names))
        tool_points = slice(geometry.stop, geometry.stop + 3 * len(tool_names))
        tool_rotations = slice(tool_points.stop, tool_points.stop + 3 * len(rotated_tools))
        effects, start = [], tool_rotations.stop
        for names in effect_names:
            effects.append(slice(start, start + len(names)))
            start += len(names)
        return cls(geometry_names=geometry_names, tool_names=tool_names,
                   rotated_tools=rotated_tools, effect_names=effect_names,
                   registration=slice(0, 6), registration_translation=slice(0, 3),
                   registration_rotation=slice(3, 6), geometry=geometry,
                   tool_points=tool_points, tool_rotations=tool_rotations,
                   effect_block=slice(tool_rotations.stop, start), effects=tuple(effects),
                   size=start)

    @property
    def n_geometric(self) -> int:
        """Unknowns before the effects: registration, geometry, tool points and rotations."""
        return self.effect_block.start

    @staticmethod
    def count(group: slice) -> int:
        """How many unknowns a group (one of the slices above) holds."""
        return group.stop - group.start

    def tool_point(self, index: int) -> slice:
        """The (x, y, z) unknowns of tool ``tool_names[index]``."""
        start = self.tool_points.start + 3 * index
        return slice(start, start + 3)

    def tool_rotation(self, index: int) -> slice:
        """The rotation-vector unknowns of tool ``rotated_tools[index]``."""
        start = self.tool_rotations.start + 3 * index
        return slice(start, start + 3)

    def names(self) -> list[str]:
        """Every unknown's name, in order."""
        tools = [f"tool.{n}.{a}" for n in self.tool_names for a in "xyz"]
        rotations = [f"tool.{n}.r{a}" for n in self.rotated_tools for a in "xyz"]
        effects = [name for names in self.effect_names for name in names]
        return [*REGISTRATION_NAMES, *self.geometry_names, *tools, *rotations, *effects]
