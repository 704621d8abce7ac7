"""Body generators: the one registry of every way the simulator makes an asteroid shape.

A generator turns (rng, target box volume, detail level) into a closed `Shape` in the body
frame (origin at the box centre). Each has continuous parameters drawn from its rng, so no two
bodies are alike; `Shape.family` is the generator's name and `Shape.params` records the drawn
parameters. `coarse` maps a generator to one of the paper's three coarse categories
(`shapes.FAMILIES`): the category stays in the data for the paper's comparison only, nothing
may need it.

    from track3d_sim.generators import GENERATORS, make_body
    shape = make_body("contact_binary", rng, volume_m3=300.0, detail=6)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .errors import SimError
from .shapes import FAMILIES, Shape, procedural_shape

__all__ = ["Generator", "GENERATORS", "register", "make_body", "generator_names", "default_generators",
           "coarse_index"]


@dataclass(frozen=True)
class Generator:
    """name: registry key (also `Shape.family` and the first half of the fine category);
    make(rng, volume_m3, detail) -> Shape; coarse: index into shapes.FAMILIES;
    star_shaped: whether every ray from the centre meets the surface once;
    description: one line for `--help` and the docs; default: in the pool a run draws from
    when `--generators` is not given (a generator added later is opt-in, so that every
    dataset made before it keeps its bodies)."""

    name: str
    make: Callable[[np.random.Generator, float, int], Shape]
    coarse: int
    star_shaped: bool
    description: str
    default: bool = True


GENERATORS: dict[str, Generator] = {}


def register(gen: Generator) -> Generator:
    if gen.name in GENERATORS:
        raise ValueError(f"generator {gen.name!r} is registered twice")
    if not 0 <= gen.coarse < len(FAMILIES):
        raise ValueError(f"generator {gen.name!r}: coarse category {gen.coarse} not in 0..{len(FAMILIES) - 1}")
    GENERATORS[gen.name] = gen
    return gen


def generator_names() -> tuple[str, ...]:
    return tuple(GENERATORS)


def default_generators() -> tuple[str, ...]:
    """The generators a run draws from when it names none (registry order)."""
    return tuple(n for n, g in GENERATORS.items() if g.default)


def coarse_index(name: str) -> int:
    """The paper's coarse category of a generator (-1 for user meshes and unknown names)."""
    g = GENERATORS.get(name)
    return g.coarse if g is not None else -1


def make_body(name: str, rng: np.random.Generator, volume_m3: float, detail: int = 6) -> Shape:
    """A body from generator `name` whose mean rotated box volume is ~`volume_m3`.

    detail: 1..8, the icosphere subdivisions of star-shaped generators; non-radial generators
    map it to a comparable mesh resolution. Raises SimError for an unknown name."""
    g = GENERATORS.get(name)
    if g is None:
        raise SimError(f"unknown shape generator {name!r} (choose from {', '.join(GENERATORS)})")
    shape = g.make(rng, float(volume_m3), int(detail))
    shape.family = g.name
    return shape


def _legacy(family: int):
    def make(rng: np.random.Generator, volume: float, detail: int) -> Shape:
        return procedural_shape(family, rng, volume, detail)
    return make


# The three star-shaped procedural families of the first release (shapes.py).
register(Generator("contact_binary", _legacy(0), 0, True, "two ellipsoidal lobes, radial p-norm union (star-shaped)"))
register(Generator("spinning_top", _legacy(1), 1, True, "double cone with an equatorial ridge (star-shaped)"))
register(Generator("irregular", _legacy(2), 2, True, "elongated, bent, saddle-dented, cratered (star-shaped)"))

# Implicit (signed distance field + marching cubes) generators: not star-shaped (bodies.py).
from . import bodies as _bodies  # noqa: E402  (the registry above must exist first)

register(Generator("bilobate", _bodies.make_bilobate, 0, False,
                   "contact binary with a concave neck, lobe ratio 0.4-0.95, bent up to 50 deg (Itokawa, 67P)"))
register(Generator("elongated", _bodies.make_elongated, 2, False,
                   "elongated body on a bent centre line, optional dog-bone waist (Eros, Kleopatra)"))
register(Generator("top_shape", _bodies.make_top_shape, 1, False,
                   "double cone blended with a sphere, equatorial ridge, many boulders (Ryugu, Bennu)"))
register(Generator("rubble_pile", _bodies.make_rubble_pile, 1, False,
                   "near-spherical or oblate lumpy spheroid strewn with boulders (Didymos)"))
register(Generator("giant_craters", _bodies.make_giant_craters, 2, False,
                   "lumpy ellipsoid with 2-5 craters as large as the body (Mathilde)"))
register(Generator("fragment", _bodies.make_fragment, 2, False,
                   "flat or angular bevelled polyhedron with conchoidal scoops (collisional fragment)"))

# Opt-in (not in the default pool; `track3d-sim generate --generators ...`).
register(Generator("superquadric", _bodies.make_superquadric, 2, False,
                   "superellipsoid from boxy to pinched, axes 1 : 0.35-1 : 0.25-0.9 (cobbles, boulders, "
                   "flattened bodies; opt-in)", default=False))
register(Generator("gaussian_sphere", _bodies.make_gaussian_sphere, 2, False,
                   "Gaussian random sphere (random log radius) stretched to 1 : 0.45-1 : 0.3-0.9, lumps and "
                   "hollows of every size (generic irregular bodies; opt-in)", default=False))
register(Generator("aggregate", _bodies.make_aggregate, 0, False,
                   "3-7 rotated superellipsoid lumps, rounded to blocky, each resting on another, sharp to "
                   "smooth contacts (aggregates, multi-lobed bodies; opt-in)", default=False))
