"""A splash from a spill with a direction (a knocked-over glass), bpy-free (tested without
Blender in tests/python): the liquid a volume thrown along a direction puts on the cloth at
the first frame, as masses per vertex whose sum is the volume's mass.

The splash is laid out in the plane tangent to the cloth at the impact point `c` (normal
`n`, the throw direction `d` projected on it, `e = n × d`); a vertex at `p` sits at
`x = (p − c)·d`, `y = (p − c)·e`, and vertices farther than `z_tol` off that plane get
nothing (the layout is for a cloth flat around the impact, as the rest pose of a cloth
usually is). Three parts share the mass `M = ρ V`:

- **The pool** (fraction `f_pool`): a puddle of the gravity-capillary thickness
  `e_p = 2 ℓ_c sin(θ/2)`, `ℓ_c = √(γ/(ρ g))` the capillary length (de Gennes,
  Brochard-Wyart & Quéré, *Capillarity and Wetting Phenomena*, 2004, §2.1.2: a large
  puddle's thickness), a disc of radius `R_p = √(f_pool V / (π e_p))` centred on `c`, flat
  on top, its edge smoothed over `w` (one mesh edge or `2 ℓ_c`, whichever is larger).
- **The tongue** (fraction `f_tongue`): the liquid leaves the tipping glass at
  `U = √(2 g H)` (the glass's height `H` above the cloth) and lands a ballistic range
  `U √(2H/g) = 2H` ahead, beyond the pool's edge: a lobe along `d` of length
  `L = R_p + 2H` whose half-width falls as `b(x) = b₀ √(1 − x/L)` (a parabolic, rounded
  nose), `b₀ = 3 f_tongue V / (4 e_p L)` so that the lobe holds its share at the pool's
  thickness (its area is `4 b₀ L / 3`); `b₀` is at most `R_p`.
- **Satellite drops** (fraction `f_drops`): the sheet's rim, decelerated at `a ≈ g`,
  has the Rayleigh–Taylor thickness `b = √(γ/(ρ a)) = ℓ_c` (Villermaux & Clanet, JFM 462,
  2002), and its ligaments break into drops of mean diameter `⟨d⟩ = 1.89 b` (the
  Rayleigh–Plateau wavelength `9.02 r` of a cylinder of radius `r = b/2` gathered into one
  drop). Diameters follow the gamma distribution of ligament-mediated fragmentation,
  `p(x) = nⁿ xⁿ⁻¹ e⁻ⁿˣ / Γ(n)`, `x = d/⟨d⟩`, `n = 4` (Villermaux, Marmottant & Duplat,
  PRL 92, 074501, 2004; Villermaux, Annu. Rev. Fluid Mech. 39, 2007), drawn until their
  volumes add up to the share (the last drop takes the remainder). Each drop leaves the
  tongue's nose at speed `U (1 + 0.2 N(0,1))`, at an elevation uniform in 10°–50° and an
  azimuth `N(0, 20°)` (clipped to ±60°) about `d`, and lands its ballistic range
  `v² sin 2α / g` ahead of the nose; a drop that would land off the cloth is re-aimed at
  half the range until it lands on it. It spreads on impact to the diameter
  `D = 0.9 d We^{1/4}`, `We = ρ v² d / γ` (Clanet, Béguin, Richard & Quéré, JFM 517,
  2004), drawn as a bump `(1 − r²/r_s²)²` of radius `r_s = max(D/2, 0.75 ℓ)` (`ℓ` the mean
  edge length, so that a drop always reaches a vertex).

Each part's profile times the vertices' areas gives its vertices' masses, scaled to the
part's mass exactly; the densities the simulator takes are these masses over the same
areas. The random numbers come from `numpy.random.default_rng(seed)` only: the same seed
gives the same splash.
"""

import math
from dataclasses import dataclass, field

import numpy as np

G = 9.81
# Gamma order of the drop sizes (Villermaux et al. 2004)
GAMMA_ORDER = 4
# mean drop diameter over the ligament (rim) thickness: (1.5 × 9.02)^(1/3)/… for a
# cylinder of diameter b breaking at the Rayleigh–Plateau wavelength 4.51 b
RP_DROP = (1.5 * 4.51) ** (1.0 / 3.0)


class SplashError(ValueError):
    """A splash that cannot be laid out (the message names the bad input)."""


@dataclass
class Splash:
    """A laid-out splash: `mass` (kg per vertex, float64), the drops' part of it
    (`drop_mass`) and what shaped it."""

    mass: np.ndarray
    impact: np.ndarray
    direction: np.ndarray
    pool_radius: float
    pool_thickness: float
    tongue_length: float
    tongue_half_width: float
    nose: np.ndarray
    drop_diameters: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drop_centres: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    part_masses: tuple = (0.0, 0.0, 0.0)
    drop_mass: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _smooth(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _normal(points, faces, near):
    """Unit area-weighted normal of the faces with a corner among `near` (bool mask)."""
    f = faces[near[faces].any(axis=1)]
    if len(f) == 0:
        f = faces
    a, b, c = (points[f[:, k]] for k in range(3))
    n = np.cross(b - a, c - a).sum(axis=0)
    length = np.linalg.norm(n)
    if not length > 0.0:
        raise SplashError("the cloth around the impact has no area (no normal)")
    return n / length


def _spread(mass, weights, what):
    """`weights` scaled to sum to `mass` exactly (float64)."""
    total = weights.sum()
    if not total > 0.0:
        raise SplashError(f"the splash's {what} reaches no vertex of the cloth")
    return weights * (mass / total)


def lay_out(points, faces, areas, impact, direction, volume, *, seed=0, height=0.1, density=1000.0,
            surface_tension=0.072, contact_angle=math.pi / 2, fractions=(0.6, 0.3, 0.1)):
    """The splash of `volume` m³ of liquid (of `density` kg/m³, `surface_tension` N/m)
    thrown along `direction` (a 3-vector, any length) from a glass `height` m tall
    standing at `impact` (a point near the cloth), on the cloth of vertices `points`
    (N, 3, metres), triangles `faces` (F, 3) and vertex `areas` (N, m², those the
    simulator multiplies the densities by): a `Splash` whose `mass` (kg per vertex) adds
    up to `density × volume`. `fractions` share the mass between the pool, the tongue
    and the drops (module doc)."""
    points = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    areas = np.asarray(areas, dtype=np.float64)
    c = np.asarray(impact, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    n_vert = len(points)
    if points.ndim != 2 or points.shape[1] != 3 or n_vert == 0:
        raise SplashError(f"the cloth's points must be an (N, 3) array, not {points.shape}")
    if areas.shape != (n_vert,):
        raise SplashError(f"the vertex areas must be ({n_vert},), not {areas.shape}")
    if not np.isfinite(points).all() or not np.isfinite(areas).all():
        raise SplashError("the cloth's points and areas must be finite")
    if not (np.isfinite(c).all() and c.shape == (3,)):
        raise SplashError(f"the impact point must be a finite 3-vector, not {c}")
    if not (np.isfinite(d).all() and d.shape == (3,)) or not np.linalg.norm(d) > 0.0:
        raise SplashError(f"the throw direction must be a finite, non-zero 3-vector, not {d}")
    for name, value in (("volume", volume), ("height", height), ("density", density),
                        ("surface tension", surface_tension)):
        if not (math.isfinite(value) and value > 0.0):
            raise SplashError(f"the splash's {name} must be finite and > 0, not {value}")
    if not 0.0 < contact_angle <= math.pi:
        raise SplashError(f"the contact angle must be in (0, π], not {contact_angle}")
    fr = np.asarray(fractions, dtype=np.float64)
    if fr.shape != (3,) or (fr < 0).any() or not math.isclose(fr.sum(), 1.0, rel_tol=1e-9) or fr[0] <= 0:
        raise SplashError(
            f"the fractions (pool, tongue, drops) must be ≥ 0, the pool's > 0, and add up to 1, not {fractions}"
        )

    total = density * volume
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edge = float(np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1).mean())
    lc = math.sqrt(surface_tension / (density * G))
    thickness = 2.0 * lc * math.sin(contact_angle / 2.0)
    r_pool = math.sqrt(fr[0] * volume / (math.pi * thickness))
    w = max(edge, 2.0 * lc)

    # the tangent plane at the vertex nearest the impact
    near_c = np.linalg.norm(points - c, axis=1)
    c = points[int(np.argmin(near_c))] + 0.0
    normal = _normal(points, faces, near_c <= max(r_pool, 2 * edge))
    c_on = c
    d = d - (d @ normal) * normal
    if not np.linalg.norm(d) > 1e-9 * np.linalg.norm(direction):
        raise SplashError("the throw direction is along the cloth's normal: it has no direction on the cloth")
    d /= np.linalg.norm(d)
    e = np.cross(normal, d)
    rel = points - c_on
    x, y, z = rel @ d, rel @ e, rel @ normal
    z_tol = max(0.25 * r_pool, 2.0 * edge)
    on = (np.abs(z) <= z_tol) & (areas > 0.0)

    # pool
    r = np.hypot(x, y)
    pool = _spread(fr[0] * total, np.where(on, _smooth((r_pool - r) / w + 0.5), 0.0) * areas, "pool")

    # tongue: from the centre to L along d
    speed = math.sqrt(2.0 * G * height)
    length = r_pool + speed * math.sqrt(2.0 * height / G)
    b0 = min(3.0 * fr[1] * volume / (4.0 * thickness * length), r_pool)
    if fr[1] > 0.0:
        inside = np.clip(1.0 - x / length, 0.0, None)
        half = b0 * np.sqrt(inside)
        along = (x >= 0.0) & (x <= length)
        prof = np.where(on & along, _smooth((half - np.abs(y)) / w + 0.5), 0.0)
        tongue = _spread(fr[1] * total, prof * areas, "tongue")
    else:
        tongue = np.zeros(n_vert)
    nose = c_on + length * d

    # drops
    rng = np.random.default_rng(seed)
    drops = np.zeros(n_vert)
    diameters, centres = [], []
    share = fr[2] * volume
    if share > 0.0:
        mean_d = RP_DROP * lc
        left = share
        while left > 0.0:
            dia = mean_d * rng.gamma(GAMMA_ORDER, 1.0 / GAMMA_ORDER)
            vol = math.pi * dia**3 / 6.0
            if vol >= left:
                vol = left
                dia = (6.0 * vol / math.pi) ** (1.0 / 3.0)
            left -= vol
            v = max(speed * (1.0 + 0.2 * rng.standard_normal()), 0.1 * speed)
            alpha = math.radians(rng.uniform(10.0, 50.0))
            phi = math.radians(float(np.clip(rng.normal(0.0, 20.0), -60.0, 60.0)))
            reach = v * v * math.sin(2.0 * alpha) / G
            heading = math.cos(phi) * d + math.sin(phi) * e
            we = density * v * v * dia / surface_tension
            r_s = max(0.45 * dia * we**0.25, 0.75 * edge)
            for _ in range(40):
                centre = nose + reach * heading
                dist = np.linalg.norm(rel - (centre - c_on), axis=1)
                dist = np.where(on, dist, np.inf)
                if dist.min() <= edge:
                    break
                reach *= 0.5
            q = dist / r_s
            bump = np.where(q < 1.0, (1.0 - q * q) ** 2, 0.0) * areas
            if not bump.sum() > 0.0:
                bump = np.zeros(n_vert)
                bump[int(np.argmin(dist))] = 1.0
            drops += _spread(density * vol, bump, "drop")
            diameters.append(dia)
            centres.append(centre)
    mass = pool + tongue + drops
    mass *= total / mass.sum()
    return Splash(
        mass=mass, impact=c_on, direction=d, pool_radius=r_pool, pool_thickness=thickness,
        tongue_length=length, tongue_half_width=b0, nose=nose,
        drop_diameters=np.array(diameters), drop_centres=np.array(centres).reshape(-1, 3),
        part_masses=(float(pool.sum()), float(tongue.sum()), float(drops.sum())), drop_mass=drops,
    )


def densities(mass, areas):
    """The liquid per unit area (kg/m², float64) that adds `mass` (kg per vertex) on
    vertices of `areas` (0 where a vertex has no area, which `lay_out` gives no mass)."""
    areas = np.asarray(areas, dtype=np.float64)
    return np.divide(mass, areas, out=np.zeros_like(areas), where=areas > 0.0)
