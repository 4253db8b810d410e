"""The food library: particle recipes per food, loaded from YAML, validated on load, sampled per episode.

A food is a recipe of one or more particle components (sphere, cube, cone or cylinder), each with
parameter ranges (size, mass, friction, restitution, contact softness) and a share of the
particle count, plus quantity levels given as physical amounts: a fill height of the source bowl
for small-particle foods, a piece count for large pieces (`QuantityLevel`). The particle count of
a fill height is derived from the bowl's inner volume up to that height, a packing fraction per
shape and the mean simulated particle volume (`level_count`). Small grains may be coarse-grained
(`ParticleComponent.coarse_grain`): simulated particles larger than the real grain by that
factor, with mass scaled by its cube (same density), so the same volume of food needs fewer
bodies, as is standard in granular simulation. Shapes are drawn once per
component per episode (one shape per batch of particles, which PyBullet creates in one call);
mass, friction and restitution are drawn per particle. The packaged library is `foods.yaml`
beside this file; users pass their own file with the same schema (`SimConfig.foods_file`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from grits_lab.config import config_from_dict, load_yaml, require
from grits_lab.errors import ConfigError, InputError
from grits_lab.sim.shapes import BowlGeometry

PACKAGED_FOODS = Path(__file__).with_name("foods.yaml")
SHAPES = ("sphere", "cube", "cone", "cylinder")
Range = tuple[float, float]
# Random loose packing fractions of settled particles (share of the bulk volume that is solid):
# spheres about 0.6; elongated and angular pieces pack looser.
PACKING_FRACTION = {"sphere": 0.60, "cube": 0.55, "cylinder": 0.52, "cone": 0.45}
MAX_PARTICLES = 2000


@dataclass
class QuantityLevel:
    """A quantity level as a physical amount: exactly one of `fill_height` or `pieces`.

    fill_height: metres of food above the source bowl's inner floor (small-particle foods); the
        particle count is the bowl's inner volume up to that height times the packing fraction,
        over the mean simulated particle volume.
    pieces: a count of large pieces.
    """

    fill_height: float | None = None
    pieces: int | None = None

    def describe(self) -> dict:
        return {"fill_height_m": self.fill_height} if self.fill_height is not None else {"pieces": self.pieces}


@dataclass
class ParticleComponent:
    """One kind of particle in a food. Lengths in metres, mass in kg; each range is [low, high]."""

    shape: Literal["sphere", "cube", "cone", "cylinder"]
    radius: Range  # real grain: sphere/cone/cylinder radius; cube half edge
    half_length: Range | None = None  # real grain: cone/cylinder half height (defaults to the radius)
    # Simulated size / real size (>= 1). Lengths are multiplied by it and masses by its cube.
    coarse_grain: float = 1.0
    fraction: float = 1.0  # share of the food's particle count
    mass: Range = (0.0005, 0.001)
    lateral_friction: Range = (0.5, 0.5)
    rolling_friction: Range = (0.001, 0.001)
    spinning_friction: Range = (0.001, 0.001)
    restitution: Range = (0.0, 0.1)
    # Contact softness (PyBullet contactStiffness / contactDamping); None keeps rigid contacts.
    contact_stiffness: float | None = None
    contact_damping: float | None = None
    color: tuple[float, float, float, float] = (0.8, 0.7, 0.5, 1.0)


@dataclass
class FoodSpec:
    """A food: its split, quantity levels (physical amounts) and particle components."""

    split: Literal["train", "unseen"]
    levels: dict[str, QuantityLevel]
    components: list[ParticleComponent]
    # Scoop success rule (paper): large pieces need one item lifted, small particles need one
    # third of the spoon covered.
    success_rule: Literal["items", "coverage"] = "coverage"
    description: str = ""


@dataclass
class SampledParticles:
    """One component's particles for one episode: a shared shape and per-particle dynamics."""

    shape: str
    radius: float
    half_length: float
    count: int
    mass: np.ndarray  # (n,)
    lateral_friction: np.ndarray
    rolling_friction: np.ndarray
    spinning_friction: np.ndarray
    restitution: np.ndarray
    contact_stiffness: float | None
    contact_damping: float | None
    color: tuple[float, float, float, float]

    @property
    def bounding_radius(self) -> float:
        if self.shape == "sphere":
            return self.radius
        if self.shape == "cube":
            return self.radius * math.sqrt(3)
        return math.hypot(self.radius, self.half_length)

    @property
    def footprint_radius(self) -> float:
        """Radius of the disc a resting particle covers on a surface (for spoon coverage)."""
        if self.shape == "sphere":
            return self.radius
        if self.shape == "cube":
            return self.radius * 1.128  # disc of the same area as the square face
        # A cone or cylinder lies on its side about as often as upright; take the mean area.
        side = math.sqrt(4 * self.radius * self.half_length / math.pi)
        return 0.5 * (self.radius + side)

    def describe(self) -> dict:
        """Scalar summary (for dataset metadata)."""
        return {
            "shape": self.shape,
            "radius": self.radius,
            "half_length": self.half_length,
            "count": self.count,
            "mass_mean": float(self.mass.mean()) if self.count else 0.0,
            "lateral_friction_mean": float(self.lateral_friction.mean()) if self.count else 0.0,
            "rolling_friction_mean": float(self.rolling_friction.mean()) if self.count else 0.0,
            "restitution_mean": float(self.restitution.mean()) if self.count else 0.0,
        }


@dataclass
class FoodLibrary:
    """All foods of a YAML file, by name."""

    foods: dict[str, FoodSpec] = field(default_factory=dict)

    def get(self, name: str) -> FoodSpec:
        if name not in self.foods:
            raise InputError(f"unknown food {name!r}; known foods: {', '.join(sorted(self.foods))}")
        return self.foods[name]

    def names(self, split: str | None = None) -> list[str]:
        return [n for n, f in self.foods.items() if split is None or f.split == split]


def _check_range(value: Range, key: str, low: float, high: float = math.inf, strict_low: bool = False) -> None:
    lo, hi = value
    ok_low = lo > low if strict_low else lo >= low
    if not (ok_low and hi <= high and lo <= hi and math.isfinite(lo) and math.isfinite(hi)):
        bound = f"> {low}" if strict_low else f">= {low}"
        limit = "" if math.isinf(high) else f" and <= {high}"
        raise ConfigError(f"`{key}` must be a range [low, high] with low <= high, values {bound}{limit}. Got {list(value)!r}.")


def validate_food(name: str, food: FoodSpec, where: str = "") -> None:
    """Range checks with messages naming the food and the key (e.g. `foods.sago.components[0].mass`)."""
    prefix = f"{where}: " if where else ""
    try:
        if not food.levels:
            raise ConfigError(f"`foods.{name}.levels` must list at least one quantity level. Got {{}}.")
        for level, amount in food.levels.items():
            key = f"foods.{name}.levels.{level}"
            if (amount.fill_height is None) == (amount.pieces is None):
                raise ConfigError(f"`{key}` must give exactly one of fill_height (metres) or pieces. Got {amount.describe()!r}.")
            if amount.fill_height is not None and not 0.002 <= amount.fill_height <= 0.055:
                raise ConfigError(f"`{key}.fill_height` must be in [0.002, 0.055] metres (the bowl is 5.9 cm deep inside). Got {amount.fill_height!r}.")
            if amount.pieces is not None and not 1 <= amount.pieces <= MAX_PARTICLES:
                raise ConfigError(f"`{key}.pieces` must be in [1, {MAX_PARTICLES}]. Got {amount.pieces!r}.")
        if not food.components:
            raise ConfigError(f"`foods.{name}.components` must list at least one particle component. Got [].")
        for i, c in enumerate(food.components):
            key = f"foods.{name}.components[{i}]"
            _check_range(c.radius, f"{key}.radius", 0.0015, 0.05)
            if c.half_length is not None:
                _check_range(c.half_length, f"{key}.half_length", 0.0015, 0.05)
            _check_range(c.mass, f"{key}.mass", 0.0, 1.0, strict_low=True)
            _check_range(c.lateral_friction, f"{key}.lateral_friction", 0.0, 5.0)
            _check_range(c.rolling_friction, f"{key}.rolling_friction", 0.0, 1.0)
            _check_range(c.spinning_friction, f"{key}.spinning_friction", 0.0, 1.0)
            _check_range(c.restitution, f"{key}.restitution", 0.0, 1.0)
            if not 1.0 <= c.coarse_grain <= 4.0:
                raise ConfigError(f"`{key}.coarse_grain` must be in [1, 4] (simulated size / real size). Got {c.coarse_grain!r}.")
            if not c.fraction > 0:
                raise ConfigError(f"`{key}.fraction` must be positive. Got {c.fraction!r}.")
            for soft in ("contact_stiffness", "contact_damping"):
                v = getattr(c, soft)
                if v is not None and not v > 0:
                    raise ConfigError(f"`{key}.{soft}` must be positive. Got {v!r}.")
            if (c.contact_stiffness is None) != (c.contact_damping is None):
                raise ConfigError(f"`{key}`: give both contact_stiffness and contact_damping, or neither.")
            if any(not 0.0 <= x <= 1.0 for x in c.color):
                raise ConfigError(f"`{key}.color` must be RGBA values in [0, 1]. Got {list(c.color)!r}.")
        for level in food.levels:
            count = level_count(food, name, level)
            if not 1 <= count <= MAX_PARTICLES:
                raise ConfigError(f"`foods.{name}.levels.{level}` makes {count} particles; it must make 1 to {MAX_PARTICLES}.")
    except ConfigError as exc:
        raise ConfigError(f"{prefix}{exc}") from None


def load_foods(path: str | Path | None = None) -> FoodLibrary:
    """Load and validate a food YAML file (the packaged library when `path` is None)."""
    path = Path(path) if path is not None else PACKAGED_FOODS
    data = load_yaml(path)
    foods = data.get("foods")
    if not isinstance(foods, dict) or not foods:
        raise ConfigError(f"{path}: top-level key `foods` must map food names to recipes")
    unknown = sorted(set(data) - {"foods"})
    if unknown:
        raise ConfigError(f"{path}: unknown top-level key `{unknown[0]}`; valid keys here: foods")
    library = FoodLibrary()
    for name, raw in foods.items():
        try:
            spec = config_from_dict(FoodSpec, raw, f"foods.{name}")
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None
        validate_food(name, spec, str(path))
        library.foods[str(name)] = spec
    return library


def particle_volume(c: ParticleComponent) -> float:
    """Mean simulated volume of one particle of `c` (m^3), coarse-graining included."""
    r = 0.5 * (c.radius[0] + c.radius[1]) * c.coarse_grain
    hl = (0.5 * (c.half_length[0] + c.half_length[1]) if c.half_length is not None else 0.5 * (c.radius[0] + c.radius[1])) * c.coarse_grain
    if c.shape == "sphere":
        return 4.0 / 3.0 * math.pi * r**3
    if c.shape == "cube":
        return 8.0 * r**3
    if c.shape == "cylinder":
        return math.pi * r**2 * 2 * hl
    return math.pi * r**2 * 2 * hl / 3.0  # cone


def bowl_volume(bowl: BowlGeometry, height: float) -> float:
    """Inner volume (m^3) of `bowl` from its inner floor up to `height` metres above it (a frustum)."""
    h = min(max(height, 0.0), bowl.depth - bowl.floor_thickness)
    r0 = bowl.floor_radius
    r1 = float(bowl.inner_radius_at(bowl.floor_thickness + h))
    return math.pi * h / 3.0 * (r0 * r0 + r0 * r1 + r1 * r1)


def fill_count(food: FoodSpec, fill_height: float, bowl: BowlGeometry | None = None) -> int:
    """Particles of `food` that fill `bowl` (default the source bowl) to `fill_height` metres.

    count = bowl_volume(h) * sum_i(f_i * packing_i) / sum_i(f_i * volume_i), with f_i the component
    fractions, packing_i the shape's random loose packing fraction and volume_i the mean
    simulated particle volume.
    """
    bowl = bowl or BowlGeometry()
    fractions = np.array([c.fraction for c in food.components], dtype=np.float64)
    fractions /= fractions.sum()
    packing = sum(f * PACKING_FRACTION[c.shape] for f, c in zip(fractions, food.components))
    volume = sum(f * particle_volume(c) for f, c in zip(fractions, food.components))
    return max(1, int(round(bowl_volume(bowl, fill_height) * packing / volume)))


def level_count(food: FoodSpec, name: str, level: str) -> int:
    """Particle count of quantity `level` of `food` (see `QuantityLevel`). Raises InputError for an unknown level."""
    if level not in food.levels:
        raise InputError(f"unknown quantity level {level!r} for food {name!r}; levels: {', '.join(food.levels)}")
    amount = food.levels[level]
    if amount.pieces is not None:
        return int(amount.pieces)
    return fill_count(food, float(amount.fill_height))


def sample_particles(food: FoodSpec, count: int, rng: np.random.Generator) -> list[SampledParticles]:
    """Draw one episode's particles: component counts by fraction, one shape per component."""
    fractions = np.array([c.fraction for c in food.components], dtype=np.float64)
    fractions /= fractions.sum()
    counts = np.floor(fractions * count).astype(int)
    counts[np.argmax(fractions)] += count - counts.sum()
    out = []
    for c, n in zip(food.components, counts):
        radius = float(rng.uniform(*c.radius)) * c.coarse_grain
        half_length = float(rng.uniform(*c.half_length)) * c.coarse_grain if c.half_length is not None else radius
        n = int(n)
        out.append(
            SampledParticles(
                shape=c.shape,
                radius=radius,
                half_length=half_length,
                count=n,
                mass=rng.uniform(*c.mass, size=n) * c.coarse_grain**3,
                lateral_friction=rng.uniform(*c.lateral_friction, size=n),
                rolling_friction=rng.uniform(*c.rolling_friction, size=n),
                spinning_friction=rng.uniform(*c.spinning_friction, size=n),
                restitution=rng.uniform(*c.restitution, size=n),
                contact_stiffness=c.contact_stiffness,
                contact_damping=c.contact_damping,
                color=tuple(c.color),
            )
        )
    return [p for p in out if p.count > 0]


@dataclass
class ParticleRanges:
    """Where `primitive_food` draws a random food's parameters: each a range [low, high].

    After the authors' generator (radius / half length 2.5-10 mm, mass 0.1-5 g, friction 0-1), in
    the coarse-grained world of `foods.yaml` (grains from 4.5 mm), with an amount drawn as a fill
    height of the source bowl. The spillage dataset's `particles` block
    (grits_lab/collection/spillage_trials.py).
    """

    radius: Range = (0.0045, 0.010)  # m, radius and half length
    mass: Range = (0.0001, 0.005)  # kg
    friction: Range = (0.0, 1.0)  # lateral friction coefficient
    fill_height: Range = (0.012, 0.032)  # m above the source bowl's inner floor

    def __post_init__(self) -> None:
        for key in ("radius", "mass", "friction", "fill_height"):
            lo, hi = getattr(self, key)
            require(0 <= lo <= hi, key, [lo, hi], "a range [low, high] with 0 <= low <= high")
        require(self.radius[0] >= 0.0015, "radius", list(self.radius), "a range starting at >= 0.0015 m")
        require(0.002 <= self.fill_height[0] and self.fill_height[1] <= 0.055, "fill_height", list(self.fill_height), "within [0.002, 0.055] metres")


def primitive_food(shape: str, rng: np.random.Generator, ranges: ParticleRanges | None = None) -> tuple[FoodSpec, int]:
    """A random single-shape food for the spillage dataset, after the authors' generator.

    Radius / half length, mass (kg), friction and an amount given as a fill height of the source
    bowl (m) are drawn uniformly in `ranges` (default `ParticleRanges()`). Ranges collapse to the
    drawn value, so the episode's particles share one parameter set. Returns the FoodSpec (one
    level, "trial") and its particle count.
    """
    if shape not in SHAPES:
        raise InputError(f"unknown particle shape {shape!r}; shapes: {', '.join(SHAPES)}")
    ranges = ranges or ParticleRanges()
    r = float(rng.uniform(*ranges.radius))
    hl = float(rng.uniform(*ranges.radius)) if shape in ("cone", "cylinder") else r
    m = float(rng.uniform(*ranges.mass))
    mu = float(rng.uniform(*ranges.friction))
    height = float(rng.uniform(*ranges.fill_height))
    comp = ParticleComponent(
        shape=shape,  # type: ignore[arg-type]
        radius=(r, r),
        half_length=(hl, hl),
        mass=(m, m),
        lateral_friction=(mu, mu),
        rolling_friction=(0.001, 0.001),
        spinning_friction=(0.001, 0.001),
        restitution=(0.05, 0.05),
        color=(0.85, 0.65, 0.3, 1.0),
    )
    spec = FoodSpec(split="train", levels={"trial": QuantityLevel(fill_height=height)}, components=[comp],
                    success_rule="items" if r >= 0.007 else "coverage", description=f"random {shape} particles")
    return spec, min(level_count(spec, "random", "trial"), MAX_PARTICLES)


def check_food_names(library: FoodLibrary, foods: list[str], levels: list[str], key_prefix: str = "") -> None:
    """Refuse, naming the key, a food the library lacks or a quantity level no listed food has.

    Foods may define different levels (orange has one), so a level is a typo only when none of
    `foods` has it.
    """
    for food in foods:
        if food not in library.foods:
            raise ConfigError(f"`{key_prefix}foods` names {food!r}, which is not in the food library "
                              f"(foods: {', '.join(sorted(library.foods))})")
    for level in levels:
        lacking = [food for food in foods if level not in library.foods[food].levels]
        if lacking and len(lacking) == len(foods):
            raise ConfigError(f"`{key_prefix}levels` names {level!r}, which food {lacking[0]!r} does not have "
                              f"(its levels: {', '.join(library.foods[lacking[0]].levels)})")
