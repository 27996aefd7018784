"""An uneven floor: a slope, gentle waves and joints (steps) of a few millimetres, as real floors.

The surface is analytic, `z = h(x, y)`, so rays hit it exactly (no heightfield cells) and a
robot resting on it gets its true height, roll and pitch from the heights under its wheels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

from pipeline.synth.objects import ObjectKind, SceneObject

FloatArray = NDArray[np.float64]
# Samples of the height along each ray's band before the root is bisected: a ray cannot enter
# and leave a floor this smooth between two samples.
_SAMPLES = 24
_BISECTIONS = 30
_NEWTON_STEPS = 4
_TOLERANCE_M = 1e-9
# Objects stand on the floor with their foot sunk this far, so no gap opens under them where the
# floor dips below the height at their centre.
SINK_M = 0.02


class FloorSpec(BaseModel):
    """What the seed draws the floor from: `waves` plane waves of random direction, amplitude and
    wavelength; a slope of random direction; `steps` straight joints of random place and rise."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    waves: int = Field(default=2, ge=0)
    wave_amplitude_m: tuple[float, float] = (0.003, 0.005)
    wave_length_m: tuple[float, float] = (1.0, 3.0)
    slope_deg: tuple[float, float] = (0.2, 0.5)
    steps: int = Field(default=1, ge=0)
    step_m: tuple[float, float] = (0.002, 0.005)
    step_distance_m: tuple[float, float] = Field(
        default=(0.5, 2.5), description="how far from the origin a joint runs"
    )

    @model_validator(mode="after")
    def _check(self) -> FloorSpec:
        for name in ("wave_amplitude_m", "wave_length_m", "slope_deg", "step_m", "step_distance_m"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(f"floor {name} must be (low, high) with 0 <= low <= high")
        if self.wave_length_m[0] <= 0:
            raise ValueError("floor wave_length_m must be positive")
        if self.slope_deg[1] >= 10:
            raise ValueError("floor slope_deg must stay under 10 deg: a ramp is not a floor")
        return self


@dataclass(frozen=True)
class FloorSurface:
    """`h(x, y) = gradient . xy + sum_w a_w sin(k_w . xy + phi_w) + sum_s rise_s [n_s . xy > c_s]`.

    `gradient` (2,); per wave `amplitude` (W,), `wave_vector` (W, 2) rad/m, `phase` (W,); per
    joint `step_normal` (S, 2) unit, `step_offset` (S,) m, `step_rise` (S,) m (the floor is
    higher by `rise` on the side the normal points to).
    """

    gradient: FloatArray
    amplitude: FloatArray
    wave_vector: FloatArray
    phase: FloatArray
    step_normal: FloatArray
    step_offset: FloatArray
    step_rise: FloatArray
    half_size_m: float

    def height(self, xy: FloatArray) -> FloatArray:
        """Floor height (N,) at `xy` (N, 2) world coordinates."""
        return self._height_and_slope(np.asarray(xy, dtype=np.float64))[0]

    def normal(self, xy: FloatArray) -> FloatArray:
        """Upward unit normals (N, 3) of the smooth part (a joint's vertical face is ignored)."""
        _, slope = self._height_and_slope(np.asarray(xy, dtype=np.float64))
        n = np.column_stack([-slope, np.ones(len(slope))])
        return np.asarray(n / np.linalg.norm(n, axis=1, keepdims=True))

    def _height_and_slope(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Height (N,) and gradient (N, 2) of the smooth part at `xy` (N, 2). Elementwise per
        wave and joint: BLAS products with an inner size of 2 cost more than they compute."""
        x, y = xy[:, 0], xy[:, 1]
        z = self.gradient[0] * x + self.gradient[1] * y
        slope = np.tile(self.gradient, (len(xy), 1))
        for a, (kx, ky), phase in zip(self.amplitude, self.wave_vector, self.phase, strict=True):
            angle = kx * x + ky * y + phase
            z = z + a * np.sin(angle)
            cos = a * np.cos(angle)
            slope[:, 0] += kx * cos
            slope[:, 1] += ky * cos
        for (nx, ny), offset, rise in zip(
            self.step_normal, self.step_offset, self.step_rise, strict=True
        ):
            z = z + np.where(nx * x + ny * y > offset, rise, 0.0)
        return z, slope

    @property
    def relief_m(self) -> float:
        """Bound on `|h - gradient . xy|`: how far the floor strays from its mean plane."""
        return float(np.sum(self.amplitude) + np.sum(np.abs(self.step_rise)))

    def intersect(
        self, origins: FloatArray, directions: FloatArray, max_range: float
    ) -> tuple[FloatArray, FloatArray]:
        """First hit of rays (`origins`, unit `directions`, (N, 3) each) with the floor inside
        its square of `half_size_m`: range (N,) (inf for a miss) and upward normal (N, 3).

        The floor lies within `relief_m` of its mean plane, so the hit lies in the stretch of
        the ray between the two offset planes. Where the ray descends faster than the waves can
        rise, the ray's height above the floor falls monotonically between joints: Newton's
        method from the mean plane's hit finds the root, and checking the ray's height just
        before each joint it crosses rules out an earlier one. Other rays (grazing ones, or
        those meeting a joint's face) are sampled along the stretch and the first crossing
        bisected.
        """
        n = len(directions)
        range_m = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        # Height of the ray above the mean plane, linear in the range s: z0 + s * rate.
        z0 = origins[:, 2] - origins[:, :2] @ self.gradient
        rate = directions[:, 2] - directions[:, :2] @ self.gradient
        relief = self.relief_m + 1e-9
        with np.errstate(divide="ignore"):
            near = np.maximum((z0 - relief) / -rate, 0.0)
        rows = np.flatnonzero((rate < -1e-9) & (z0 + relief > 0) & (near <= max_range))
        if len(rows) == 0:
            return range_m, normal
        o, d, z, r = origins[rows], directions[rows], z0[rows], rate[rows]
        near, far = near[rows], (z + relief) / -r
        s, solved = self._newton(o, d, z, r, near, far)
        if not solved.all():
            rest = np.flatnonzero(~solved)
            s[rest] = self._bisect(o[rest], d[rest], near[rest], far[rest])
        hit = o + d * s[:, None]
        inside = np.all(np.abs(hit[:, :2]) <= self.half_size_m, axis=1)
        ok = np.isfinite(s) & inside & (s <= max_range)
        range_m[rows[ok]] = s[ok]
        normal[rows[ok]] = self.normal(hit[ok, :2])
        return range_m, normal

    def _gap(self, o: FloatArray, d: FloatArray, s: FloatArray) -> FloatArray:
        """Height (N,) of the ray points at ranges `s` (N,) above the floor."""
        p = o + d * s[:, None]
        return np.asarray(p[:, 2] - self.height(p[:, :2]))

    def _newton(
        self,
        o: FloatArray,
        d: FloatArray,
        z: FloatArray,
        r: FloatArray,
        near: FloatArray,
        far: FloatArray,
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Roots (N,) and whether each is surely the ray's first hit (N,)."""
        wave_rise = np.abs(self.amplitude) @ np.linalg.norm(self.wave_vector, axis=1)
        monotone = -r > 2.0 * wave_rise * np.linalg.norm(d[:, :2], axis=1)
        s = np.clip(-z / r, near, far)
        for _ in range(_NEWTON_STEPS):
            p = o + d * s[:, None]
            height, slope = self._height_and_slope(p[:, :2])
            rate = d[:, 2] - np.einsum("ij,ij->i", slope, d[:, :2])
            s = np.clip(s - (p[:, 2] - height) / rate, near, far)
        solved = monotone & (np.abs(self._gap(o, d, s)) < _TOLERANCE_M)
        with np.errstate(divide="ignore", invalid="ignore"):
            for normal, offset in zip(self.step_normal, self.step_offset, strict=True):
                crossing = (offset - o[:, :2] @ normal) / (d[:, :2] @ normal)
                before = (crossing > near) & (crossing < s)
                rows = np.flatnonzero(solved & before)
                if len(rows):
                    ahead = self._gap(o[rows], d[rows], crossing[rows] - _TOLERANCE_M)
                    solved[rows[ahead <= 0]] = False
        return s, solved

    def _bisect(
        self, o: FloatArray, d: FloatArray, near: FloatArray, far: FloatArray
    ) -> FloatArray:
        """First crossing (N,) of each ray into the floor between `near` and `far` (inf: none)."""
        grid = near[:, None] + (far - near)[:, None] * np.linspace(0.0, 1.0, _SAMPLES)[None, :]
        above = self._above(o, d, grid)
        crossing = ~above[:, 1:] & above[:, :-1]
        found = crossing.any(axis=1) & above[:, 0]
        first = np.argmax(crossing, axis=1)
        lo = grid[np.arange(len(o)), first]
        hi = grid[np.arange(len(o)), first + 1]
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            up = self._above(o, d, mid[:, None])[:, 0]
            lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
        return np.where(found, hi, np.inf)

    def _above(
        self, origins: FloatArray, directions: FloatArray, s: FloatArray
    ) -> NDArray[np.bool_]:
        """Whether the ray points at ranges `s` (N, M) lie above the floor, (N, M)."""
        points = origins[:, None, :] + directions[:, None, :] * s[:, :, None]
        heights = self.height(points[:, :, :2].reshape(-1, 2)).reshape(s.shape)
        return np.asarray(points[:, :, 2] > heights)

    def rest(
        self, T_world_planar: NDArray[np.float64], footprint_m: tuple[float, float]
    ) -> NDArray[np.float64]:
        """Poses (K, 4, 4) of a robot resting on the floor, from its planar poses (K, 4, 4)
        (x, y, yaw; z, roll and pitch ignored): the plane fitted through the floor heights under
        its four wheels (corners of `footprint_m`, length and width) sets its height at the base
        origin and its roll and pitch; the origin stays above the planar position."""
        half_x, half_y = 0.5 * footprint_m[0], 0.5 * footprint_m[1]
        wheels = np.array(
            [[half_x, half_y], [half_x, -half_y], [-half_x, half_y], [-half_x, -half_y]]
        )
        yaw = np.arctan2(T_world_planar[:, 1, 0], T_world_planar[:, 0, 0])
        cos, sin = np.cos(yaw), np.sin(yaw)
        R_yaw = np.zeros((len(yaw), 3, 3))
        R_yaw[:, 0, 0], R_yaw[:, 0, 1], R_yaw[:, 1, 0], R_yaw[:, 1, 1] = cos, -sin, sin, cos
        R_yaw[:, 2, 2] = 1.0
        xy = T_world_planar[:, None, :2, 3] + np.einsum("kij,wj->kwi", R_yaw[:, :2, :2], wheels)
        heights = self.height(xy.reshape(-1, 2)).reshape(len(yaw), 4)
        # z = a + b u + c v in the base's heading frame (u forward, v left): least squares.
        design = np.column_stack([np.ones(4), wheels])
        a, b, c = np.linalg.lstsq(design, heights.T, rcond=None)[0]
        x_axis = np.column_stack([np.ones_like(b), np.zeros_like(b), b])
        z_axis = np.column_stack([-b, -c, np.ones_like(b)])
        x_axis /= np.linalg.norm(x_axis, axis=1, keepdims=True)
        z_axis /= np.linalg.norm(z_axis, axis=1, keepdims=True)
        y_axis = np.cross(z_axis, x_axis)
        T = np.zeros_like(T_world_planar)
        T[:, :3, :3] = R_yaw @ np.stack([x_axis, y_axis, z_axis], axis=2)
        T[:, :2, 3] = T_world_planar[:, :2, 3]
        T[:, 2, 3] = a
        T[:, 3, 3] = 1.0
        return T

    def stand(self, obj: SceneObject) -> SceneObject:
        """`obj` (made for a flat floor at z = 0) standing on this floor: raised to the floor
        height at its centre, upright ones lengthened to reach `SINK_M` into the floor."""
        T = obj.T_world_object.copy()
        ground = float(self.height(T[None, :2, 3])[0])
        dimensions = dict(obj.dimensions)
        if obj.kind is ObjectKind.CAPSULE:
            T[2, 3] += ground
        else:
            key = "z" if obj.kind is ObjectKind.BOX else "height"
            top = T[2, 3] + 0.5 * dimensions[key] + ground
            dimensions[key] += SINK_M
            T[2, 3] = top - 0.5 * dimensions[key]
        return SceneObject(obj.kind, dimensions, T, obj.reflectivity, obj.role)

    def to_json(self) -> dict[str, Any]:
        return {
            "model": "h(x, y) = gradient . xy + sum a sin(k . xy + phase) + sum rise [n . xy > c]",
            "gradient": self.gradient.tolist(),
            "slope_deg": math.degrees(math.atan(float(np.linalg.norm(self.gradient)))),
            "waves": [
                {"amplitude_m": float(a), "wave_vector": k.tolist(), "phase": float(p)}
                for a, k, p in zip(self.amplitude, self.wave_vector, self.phase, strict=True)
            ],
            "steps": [
                {"normal": nrm.tolist(), "offset_m": float(c), "rise_m": float(r)}
                for nrm, c, r in zip(
                    self.step_normal, self.step_offset, self.step_rise, strict=True
                )
            ],
            "half_size_m": self.half_size_m,
        }

    @staticmethod
    def from_json(doc: dict[str, Any]) -> FloorSurface:
        waves, steps = doc["waves"], doc["steps"]
        return FloorSurface(
            gradient=np.asarray(doc["gradient"], dtype=np.float64),
            amplitude=np.array([w["amplitude_m"] for w in waves], dtype=np.float64),
            wave_vector=np.array([w["wave_vector"] for w in waves], dtype=np.float64).reshape(
                -1, 2
            ),
            phase=np.array([w["phase"] for w in waves], dtype=np.float64),
            step_normal=np.array([s["normal"] for s in steps], dtype=np.float64).reshape(-1, 2),
            step_offset=np.array([s["offset_m"] for s in steps], dtype=np.float64),
            step_rise=np.array([s["rise_m"] for s in steps], dtype=np.float64),
            half_size_m=float(doc["half_size_m"]),
        )


def draw_floor(spec: FloorSpec, rng: np.random.Generator, half_size_m: float) -> FloorSurface:
    """A floor surface drawn from `spec`."""

    def directions(count: int) -> FloatArray:
        angle = rng.uniform(-math.pi, math.pi, size=count)
        return np.column_stack([np.cos(angle), np.sin(angle)])

    slope = math.tan(math.radians(rng.uniform(*spec.slope_deg)))
    length = rng.uniform(*spec.wave_length_m, size=spec.waves)
    return FloorSurface(
        gradient=slope * directions(1)[0],
        amplitude=rng.uniform(*spec.wave_amplitude_m, size=spec.waves),
        wave_vector=directions(spec.waves) * (2.0 * math.pi / length)[:, None],
        phase=rng.uniform(0.0, 2.0 * math.pi, size=spec.waves),
        step_normal=directions(spec.steps),
        step_offset=rng.uniform(*spec.step_distance_m, size=spec.steps),
        step_rise=rng.uniform(*spec.step_m, size=spec.steps),
        half_size_m=half_size_m,
    )
