"""The registry of built-in objects (:data:`OBJECTS`) and :func:`get_object` (built, cached)."""

from __future__ import annotations

import difflib
import functools
from collections.abc import Iterator, Mapping, Sequence

from handsim.errors import UnknownName
from handsim.world.objects import (
    N_MODEL_POINTS,
    ObjectSpec,
    YCBObject,
    _check_sampling,
    _Geometry,
)
from handsim.world.ycbv import _FACTS, _RECIPES, _SYMMETRY_KINDS

__all__ = [
    "ObjectRegistry",
    "OBJECTS",
    "OBJECT_NAMES",
    "get_object",
]


class ObjectRegistry(Mapping[str, ObjectSpec]):
    """The registered objects by canonical name (``005_tomato_soup_can``), in YCB-V id order.

    Look-ups also accept the short alias (``tomato_soup_can``) and the MJCF body name
    (``obj_005_tomato_soup_can``); iteration yields each canonical name once. An unknown name
    raises :class:`~handsim.errors.UnknownName` listing the valid names.
    """

    def __init__(self, specs: Sequence[ObjectSpec]) -> None:
        self._specs = {s.name: s for s in specs}
        self._aliases = {s.alias: s.name for s in specs}

    def canonical(self, name: str) -> str:
        """The canonical name of ``name`` (canonical, alias or ``obj_`` body name).

        Raises:
            UnknownName: if no object has that name.
        """
        if isinstance(name, str):
            key = name[4:] if name.startswith("obj_") else name
            if key in self._specs:
                return key
            if key in self._aliases:
                return self._aliases[key]
        known = list(self._specs) + list(self._aliases)
        close = difflib.get_close_matches(str(name), known, n=3)
        hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise UnknownName(
            f"unknown object {name!r}.{hint} Valid names: {', '.join(self._specs)} "
            f"(each also without its number, e.g. 'tomato_soup_can')."
        )

    def __getitem__(self, name: str) -> ObjectSpec:
        return self._specs[self.canonical(name)]

    def __contains__(self, name: object) -> bool:
        try:
            self.canonical(name)  # type: ignore[arg-type]
        except UnknownName:
            return False
        return True

    def __iter__(self) -> Iterator[str]:
        return iter(self._specs)

    def __len__(self) -> int:
        return len(self._specs)

    def __repr__(self) -> str:
        return f"ObjectRegistry({list(self._specs)})"


OBJECTS = ObjectRegistry(
    [
        ObjectSpec(
            name=name,
            ycbv_id=ycbv_id,
            extents_m=tuple(e / 1000 for e in extents_mm),
            diameter_m=diameter_mm / 1000,
            mass_kg=mass_g / 1000,
            shape=_RECIPES[name][1],
            symmetry_kind=_SYMMETRY_KINDS.get(name, "none"),
            rgba=_RECIPES[name][2],
            _builder=_RECIPES[name][0],
        )
        for ycbv_id, name, extents_mm, diameter_mm, mass_g in _FACTS
    ]
)
"""The 21 YCB-Video objects (:class:`ObjectRegistry` of :class:`ObjectSpec`)."""

OBJECT_NAMES: tuple[str, ...] = tuple(OBJECTS)
"""Canonical names of the registered objects, in YCB-Video id order."""


def get_object(name: str, *, n_model_points: int = N_MODEL_POINTS, seed: int = 0) -> YCBObject:
    """A built-in object by name (canonical, short alias or ``obj_`` body name); cached.

    Args:
        name: e.g. ``"005_tomato_soup_can"`` or ``"tomato_soup_can"``.
        n_model_points: number of surface samples in ``model_points_m``.
        seed: seed of the surface sampling.

    Raises:
        UnknownName: if ``name`` is not registered (the message lists the valid names).
        InvalidObjectParams: if ``n_model_points`` or ``seed`` is invalid.
    """
    canonical = OBJECTS.canonical(name)
    _check_sampling(n_model_points, seed)
    return _build_cached(canonical, int(n_model_points), int(seed))


@functools.lru_cache(maxsize=64)
def _build_cached(name: str, n_model_points: int, seed: int) -> YCBObject:
    return OBJECTS[name]._finish(_geometry_cached(name), n_model_points, seed)


@functools.cache
def _geometry_cached(name: str) -> _Geometry:
    # The meshes are copied by _finalize, so one geometry serves every sampling.
    return OBJECTS[name]._builder()
