"""Face models: a neutral mesh plus linear displacement bases (animation and shape units).

A face model deforms linearly (the Candide-3 convention)::

    v = v0 + sum_s sigma_s * SU_s + sum_a alpha_a * AU_a          (all (n, 3), model units)

The four mouth parameters of :data:`realtime_core.VISUAL_PARAMS` are *geometric* quantities
measured on any face in units of its inter-ocular distance (IOD), so they mean the same on every
model. :func:`measure_mouth` measures them from a neutral and a deformed pose and
:func:`calibrate_mouth` measures the model's response to each chosen unit (group) once and inverts
it by least squares, giving the linear map params (4,) -> unit weights (k,). Because both the
measurement (to first order) and the deformation are linear, the whole chain params -> vertex
displacement collapses into one (n*3, 4) matrix, :meth:`MouthCalibration.basis`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from realtime_core.errors import ConfigError, ModelFormatError

N_PARAMS = 4


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _check_units(kind: str, units: Mapping[str, np.ndarray], n: int) -> Mapping[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for name, d in units.items():
        d = np.asarray(d, dtype=np.float64)
        if d.shape != (n, 3):
            raise ModelFormatError(f"{kind} {name!r} has shape {d.shape}, expected ({n}, 3)")
        if not np.all(np.isfinite(d)):
            raise ModelFormatError(f"{kind} {name!r} contains non-finite values")
        out[str(name)] = _readonly(d)
    return MappingProxyType(out)


@dataclass(frozen=True)
class FaceModel:
    """A triangle mesh with named linear deformation bases.

    vertices: (n, 3) float64 neutral positions (model units, any right-handed frame).
    triangles: (m, 3) int64 vertex indices.
    uvs: optional (n, 2) float64 texture coordinates.
    animation_units / shape_units: name -> (n, 3) float64 displacement per unit weight.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    uvs: np.ndarray | None = None
    animation_units: Mapping[str, np.ndarray] = field(default_factory=dict)
    shape_units: Mapping[str, np.ndarray] = field(default_factory=dict)
    name: str = ""

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise ModelFormatError(f"face model vertices must be (n, 3) with n > 0, got {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ModelFormatError("face model vertices contain non-finite values")
        t = np.asarray(self.triangles)
        if t.size == 0:
            t = np.zeros((0, 3), dtype=np.int64)
        if t.ndim != 2 or t.shape[1] != 3 or not np.issubdtype(t.dtype, np.integer):
            raise ModelFormatError(f"face model triangles must be (m, 3) integers, got {t.shape} {t.dtype}")
        if t.size and (t.min() < 0 or t.max() >= len(v)):
            raise ModelFormatError(f"triangle indices out of range [0, {len(v)})")
        uv = None
        if self.uvs is not None:
            uv = np.asarray(self.uvs, dtype=np.float64)
            if uv.shape != (len(v), 2):
                raise ModelFormatError(f"uvs have shape {uv.shape}, expected ({len(v)}, 2)")
            uv = _readonly(uv)
        object.__setattr__(self, "vertices", _readonly(v))
        object.__setattr__(self, "triangles", _readonly(t.astype(np.int64)))
        object.__setattr__(self, "uvs", uv)
        object.__setattr__(self, "animation_units", _check_units("animation unit", self.animation_units, len(v)))
        object.__setattr__(self, "shape_units", _check_units("shape unit", self.shape_units, len(v)))

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    def deform(
        self,
        weights: Mapping[str, float] | None = None,
        *,
        shape: Mapping[str, float] | None = None,
    ) -> np.ndarray:
        """Deformed vertices (n, 3) float64 for animation-unit ``weights`` and shape-unit ``shape``.

        Unknown unit names raise :class:`ConfigError`; missing names have weight 0.
        """
        out = np.array(self.vertices, dtype=np.float64)
        for table, kind, w in (
            (self.shape_units, "shape unit", shape),
            (self.animation_units, "animation unit", weights),
        ):
            for name, value in (w or {}).items():
                if name not in table:
                    raise ConfigError(f"unknown {kind} {name!r}")
                out += float(value) * table[name]
        return out

    def with_neutral(self, vertices: np.ndarray) -> FaceModel:
        """The same model with new neutral vertices (n, 3) (e.g. after registration/shape fit)."""
        return FaceModel(
            vertices=vertices,
            triangles=self.triangles,
            uvs=self.uvs,
            animation_units=self.animation_units,
            shape_units=self.shape_units,
            name=self.name,
        )

    def transformed(self, scale: float, rotation: np.ndarray, translation: np.ndarray) -> FaceModel:
        """The model under x -> scale * R x + t; units are rotated and scaled too (not translated)."""
        r = np.asarray(rotation, dtype=np.float64)

        def lin(d: np.ndarray) -> np.ndarray:
            return scale * d @ r.T

        return FaceModel(
            vertices=lin(self.vertices) + np.asarray(translation, dtype=np.float64),
            triangles=self.triangles,
            uvs=self.uvs,
            animation_units={k: lin(d) for k, d in self.animation_units.items()},
            shape_units={k: lin(d) for k, d in self.shape_units.items()},
            name=self.name,
        )


@dataclass(frozen=True)
class MouthLandmarks:
    """Vertex indices that define the mouth parameters on one model.

    Outer lip midpoints, inner lip midpoints (the edges that part when the mouth opens), the two
    mouth corners, and the inner/outer corners of both eyes (their midpoints are the eye centres
    whose distance is the IOD). "left" is the face's own left.
    """

    upper_lip: int
    lower_lip: int
    upper_inner: int
    lower_inner: int
    corner_left: int
    corner_right: int
    eye_outer_left: int
    eye_inner_left: int
    eye_outer_right: int
    eye_inner_right: int

    def __post_init__(self) -> None:
        for k, v in self.as_dict().items():
            if int(v) != v or v < 0:
                raise ConfigError(f"landmark {k} must be a non-negative vertex index, got {v!r}")

    @classmethod
    def among(cls, names: Mapping[str, int]) -> MouthLandmarks:
        """The mouth landmarks among named landmark vertex indices (extra names ignored)."""
        return cls(**{k: int(names[k]) for k in cls.__dataclass_fields__})

    def as_dict(self) -> dict[str, int]:
        return {k: int(getattr(self, k)) for k in self.__dataclass_fields__}

    def check(self, n_vertices: int) -> None:
        bad = {k: v for k, v in self.as_dict().items() if v >= n_vertices}
        if bad:
            raise ConfigError(f"landmark indices out of range for {n_vertices} vertices: {bad}")


@dataclass(frozen=True)
class FaceFrame:
    """A face-centred orthonormal frame: x to the face's left, y up, z out of the face; iod in model units."""

    origin: np.ndarray  # (3,)
    axes: np.ndarray  # (3, 3) rows x, y, z
    iod: float


def face_frame(neutral: np.ndarray, lm: MouthLandmarks) -> FaceFrame:
    """The frame (x: right eye -> left eye, y: mouth -> eyes, orthogonalised; z = x cross y) of (n, 3) ``neutral``."""
    v = np.asarray(neutral, dtype=np.float64)
    lm.check(len(v))
    return face_frame_at(
        eye_left=0.5 * (v[lm.eye_outer_left] + v[lm.eye_inner_left]),
        eye_right=0.5 * (v[lm.eye_outer_right] + v[lm.eye_inner_right]),
        mouth=0.5 * (v[lm.corner_left] + v[lm.corner_right]),
    )


def inner_lip_gap(vertices: np.ndarray, upper_inner: int, lower_inner: int, frame: FaceFrame) -> float:
    """IOD: how far the upper inner-lip vertex lies above the lower one along ``frame``'s up axis in ``vertices``
    (n, 3) (negative: pressed past each other): the lips' gap every closure figure and rest rule reads."""
    v = np.asarray(vertices)
    return float((v[upper_inner] - v[lower_inner]) @ frame.axes[1]) / frame.iod


def face_frame_at(*, eye_left: np.ndarray, eye_right: np.ndarray, mouth: np.ndarray) -> FaceFrame:
    """:func:`face_frame` from the two eye centres and the mouth centre, each (3,) (points off any mesh)."""
    el, er = np.asarray(eye_left, dtype=np.float64), np.asarray(eye_right, dtype=np.float64)
    iod = float(np.linalg.norm(el - er))
    if not iod > 0:
        raise ConfigError("eye centres coincide: inter-ocular distance is zero")
    x = (el - er) / iod
    up = 0.5 * (el + er) - np.asarray(mouth, dtype=np.float64)
    up = up - x * (up @ x)
    nu = np.linalg.norm(up)
    if not nu > 1e-9 * iod:
        raise ConfigError("mouth lies on the eye line: cannot define the face's up direction")
    y = up / nu
    z = np.cross(x, y)
    return FaceFrame(origin=0.5 * (el + er), axes=np.stack([x, y, z]), iod=iod)


def measure_mouth(neutral: np.ndarray, deformed: np.ndarray, lm: MouthLandmarks) -> np.ndarray:
    """The four mouth parameters (4,) float64, in IOD units, of ``deformed`` relative to ``neutral`` (both (n, 3)).

    upper_lip_raise: upward motion of the outer upper-lip midpoint; lip_stretch: change of the
    corner-to-corner distance; mouth_open: change of the inner-lip vertical gap;
    lip_corner_depress: downward motion of the mean corner relative to the mean outer-lip midpoint.
    Up and the IOD come from the neutral pose, so the numbers are invariant to a similarity
    transform applied to both poses.
    """
    v0 = np.asarray(neutral, dtype=np.float64)
    v1 = np.asarray(deformed, dtype=np.float64)
    if v0.shape != v1.shape:
        raise ConfigError(f"neutral {v0.shape} and deformed {v1.shape} differ in shape")
    fr = face_frame(v0, lm)
    up = fr.axes[1]
    d = v1 - v0
    raise_ = d[lm.upper_lip] @ up
    w0 = np.linalg.norm(v0[lm.corner_left] - v0[lm.corner_right])
    w1 = np.linalg.norm(v1[lm.corner_left] - v1[lm.corner_right])
    gap0 = (v0[lm.upper_inner] - v0[lm.lower_inner]) @ up
    gap1 = (v1[lm.upper_inner] - v1[lm.lower_inner]) @ up
    corners = 0.5 * (d[lm.corner_left] + d[lm.corner_right]) @ up
    mid = 0.5 * (d[lm.upper_lip] + d[lm.lower_lip]) @ up
    return np.array([raise_, w1 - w0, gap1 - gap0, mid - corners], dtype=np.float64) / fr.iod


@dataclass(frozen=True)
class MouthCalibration:
    """Linear map from the 4 mouth parameters to the weights of k unit groups.

    groups: k tuples of animation-unit names whose weights move together (e.g. a left and a
    right unit). response: (4, k) parameters produced by weight 1 of each group.
    matrix: (k, 4) least-squares inverse, weights = matrix @ params.
    """

    groups: tuple[tuple[str, ...], ...]
    response: np.ndarray
    matrix: np.ndarray

    def weights(self, params: np.ndarray) -> dict[str, float]:
        """Animation-unit weights for mouth ``params`` (4,) in IOD units."""
        p = np.asarray(params, dtype=np.float64).reshape(N_PARAMS)
        g = self.matrix @ p
        out: dict[str, float] = {}
        for names, w in zip(self.groups, g):
            for n in names:
                out[n] = out.get(n, 0.0) + float(w)
        return out

    def basis(self, model: FaceModel) -> np.ndarray:
        """(n*3, 4) float64 B with displacement.ravel() = B @ params for ``model``'s units."""
        cols = []
        for names in self.groups:
            cols.append(np.sum([model.animation_units[n] for n in names], axis=0).reshape(-1))
        unit = np.stack(cols, axis=1)  # (n*3, k)
        return unit @ self.matrix


def calibrate_mouth(
    model: FaceModel,
    landmarks: MouthLandmarks,
    *,
    groups: Sequence[Sequence[str]],
    probe: float = 1.0,
) -> MouthCalibration:
    """Measure ``model``'s mouth response to each unit group at weight ``probe`` and invert it.

    groups: k >= 4 sequences of animation-unit names (one group per parameter is typical).
    Raises ConfigError if a unit is unknown or the response (4, k) has rank < 4 (some parameter
    cannot be produced by these units).
    """
    if not probe > 0:
        raise ConfigError(f"probe weight must be > 0, got {probe}")
    gs = tuple(tuple(str(n) for n in g) for g in groups)
    if len(gs) < N_PARAMS:
        raise ConfigError(f"need at least {N_PARAMS} unit groups, got {len(gs)}")
    landmarks.check(model.n_vertices)
    resp = np.zeros((N_PARAMS, len(gs)))
    for j, names in enumerate(gs):
        for n in names:
            if n not in model.animation_units:
                raise ConfigError(f"unknown animation unit {n!r} in calibration group {names}")
        deformed = model.deform({n: probe for n in names})
        resp[:, j] = measure_mouth(model.vertices, deformed, landmarks) / probe
    s = np.linalg.svd(resp, compute_uv=False)
    if s[-1] < 1e-6 * s[0]:
        raise ConfigError(f"unit groups {gs} cannot produce all four mouth parameters (singular values {s})")
    return MouthCalibration(groups=gs, response=_readonly(resp), matrix=_readonly(np.linalg.pinv(resp)))
