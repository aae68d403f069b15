"""Articulated walking human meshes built from primitives.

A person is a fixed set of rigid segments (torso, pelvis, neck, head, hair, and for each
side an upper arm, a forearm with hand, a thigh, a shin and a foot). Each segment's
triangle mesh is built once at import time in a *template* body of height 1 with its
joint at the origin; per frame :func:`people_mesh` only rotates the limb segments about
their joints (all joint rotations are about the body's lateral axis, so the forward
kinematics is a chain of planar rotations), scales the body to the person's height,
turns it to the heading and places it at the person's floor position.

Body frame: x forward (the heading), y left, z up, feet on the floor ``z = 0``. The world
frame is Z up in metres (:mod:`dynactivegs.records`); a heading of ``h`` radians points the
body's x axis along ``(cos h, sin h)``.

Gait: with phase ``phi`` (radians, 2 pi per stride of two steps) the left hip flexes by
``A sin(phi)`` and the right by ``-A sin(phi)``; knees flex during swing; arms swing
opposite to the leg on the same side with a slight elbow bend. Amplitudes grow with speed
and are zero when standing still, so a standing person has straight limbs. After the
kinematics the body is lifted so that the lower foot's sole is exactly on the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# ---------------------------------------------------------------------------------------
# Looks

_SKIN_TONES = np.array([          # sRGB, from very light to very dark
    (255, 224, 196), (241, 194, 160), (224, 172, 134), (198, 134, 96),
    (168, 110, 74), (141, 85, 52), (110, 66, 40), (78, 46, 28),
], dtype=np.float64)
_HAIR_COLORS = np.array([
    (20, 16, 14), (45, 30, 20), (85, 55, 30), (130, 90, 50), (190, 150, 90),
    (150, 60, 30), (120, 120, 120), (210, 210, 205),
], dtype=np.float64)
_SHIRT_COLORS = np.array([
    (200, 30, 40), (30, 80, 170), (40, 140, 70), (235, 200, 40), (240, 240, 235),
    (25, 25, 30), (120, 60, 150), (240, 130, 40), (90, 170, 210), (150, 150, 155),
    (220, 120, 160), (100, 70, 45),
], dtype=np.float64)
_TROUSER_COLORS = np.array([
    (35, 45, 80), (20, 20, 25), (95, 95, 100), (160, 140, 100), (60, 70, 50),
    (110, 70, 45), (70, 100, 150), (200, 195, 180),
], dtype=np.float64)
_SHOE_COLORS = np.array([
    (15, 15, 15), (240, 240, 240), (90, 55, 30), (60, 60, 70), (170, 40, 40), (30, 60, 120),
], dtype=np.float64)


@dataclass(frozen=True, slots=True)
class HumanLook:
    """How one person looks: height and the colours of skin, clothes and hair (sRGB 0-255)."""

    height_m: float                   # standing height, top of the hair, in [1.6, 1.9]
    skin_rgb: tuple[int, int, int]
    shirt_rgb: tuple[int, int, int]
    trousers_rgb: tuple[int, int, int]
    shoes_rgb: tuple[int, int, int]
    hair_rgb: tuple[int, int, int]

    def __post_init__(self) -> None:
        if not 1.6 <= self.height_m <= 1.9:
            raise ValueError(f"HumanLook.height_m must be in [1.6, 1.9] m; got {self.height_m}")
        for name in ("skin_rgb", "shirt_rgb", "trousers_rgb", "shoes_rgb", "hair_rgb"):
            c = getattr(self, name)
            if len(c) != 3 or not all(0 <= int(v) <= 255 for v in c):
                raise ValueError(f"HumanLook.{name} must be three ints in [0, 255]; got {c}")

    def palette(self) -> np.ndarray:
        """uint8 (5, 3): colours indexed by the segment material ids (skin, shirt, trousers, shoes, hair)."""
        return np.array([self.skin_rgb, self.shirt_rgb, self.trousers_rgb, self.shoes_rgb, self.hair_rgb],
                        dtype=np.uint8)


def _jitter(rng: np.random.Generator, base: np.ndarray, amount: float) -> tuple[int, int, int]:
    c = base * rng.uniform(1.0 - amount, 1.0 + amount) + rng.normal(0.0, 6.0, size=3)
    return tuple(int(v) for v in np.clip(np.round(c), 0, 255))  # type: ignore[return-value]


def sample_look(rng: np.random.Generator) -> HumanLook:
    """A random look: height U(1.6, 1.9) m, a skin tone from light to dark, varied clothing colours."""
    height = float(rng.uniform(1.6, 1.9))
    skin = _SKIN_TONES[rng.integers(len(_SKIN_TONES))]
    hair = _HAIR_COLORS[rng.integers(len(_HAIR_COLORS))]
    shirt = _SHIRT_COLORS[rng.integers(len(_SHIRT_COLORS))]
    trousers = _TROUSER_COLORS[rng.integers(len(_TROUSER_COLORS))]
    shoes = _SHOE_COLORS[rng.integers(len(_SHOE_COLORS))]
    return HumanLook(
        height_m=height,
        skin_rgb=_jitter(rng, skin, 0.06),
        shirt_rgb=_jitter(rng, shirt, 0.15),
        trousers_rgb=_jitter(rng, trousers, 0.12),
        shoes_rgb=_jitter(rng, shoes, 0.10),
        hair_rgb=_jitter(rng, hair, 0.10),
    )


# ---------------------------------------------------------------------------------------
# Primitive meshes (closed, faces wound counter-clockwise seen from outside)

def _surface_of_revolution(profile_rz: np.ndarray, n_sides: int, rx: float = 1.0,
                           ry: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed mesh revolving ``profile_rz (K, 2)`` (radius, z), ordered from the top pole down.

    The first and last profile points must have radius 0 (poles). ``rx``, ``ry`` scale the
    cross-section into an ellipse. Returns vertices (V, 3) and faces (F, 3).
    """
    r, z = profile_rz[:, 0], profile_rz[:, 1]
    assert r[0] == 0.0 and r[-1] == 0.0 and len(r) >= 3
    ang = 2.0 * np.pi * np.arange(n_sides) / n_sides
    rings = profile_rz[1:-1]
    ring_v = np.stack([
        (rings[:, 0:1] * rx * np.cos(ang)[None]).ravel(),
        (rings[:, 0:1] * ry * np.sin(ang)[None]).ravel(),
        np.repeat(rings[:, 1], n_sides),
    ], axis=1)
    verts = np.concatenate([[[0.0, 0.0, z[0]]], ring_v, [[0.0, 0.0, z[-1]]]])
    n_rings = len(rings)
    top, bottom = 0, len(verts) - 1
    faces = []
    k = np.arange(n_sides)
    k1 = (k + 1) % n_sides
    # top fan: pole, ring0[k], ring0[k+1] is CCW seen from above (outside)
    faces.append(np.stack([np.full(n_sides, top), 1 + k, 1 + k1], axis=1))
    for i in range(n_rings - 1):
        a = 1 + i * n_sides
        b = a + n_sides
        faces.append(np.stack([a + k, b + k, b + k1], axis=1))
        faces.append(np.stack([a + k, b + k1, a + k1], axis=1))
    last = 1 + (n_rings - 1) * n_sides
    faces.append(np.stack([np.full(n_sides, bottom), last + k1, last + k], axis=1))
    return verts, np.concatenate(faces).astype(np.int64)


def _capsule(radius: float, length: float, n_sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A capsule hanging from the origin along -z: cap centres at z=0 and z=-length."""
    c = math.cos(math.pi / 4) * radius
    profile = np.array([
        (0.0, radius), (c, c), (radius, 0.0),
        (radius, -length), (c, -length - c), (0.0, -length - radius),
    ])
    return _surface_of_revolution(profile, n_sides)


def _ellipsoid(rx: float, ry: float, rz: float, n_sides: int, n_lat: int) -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid centred at the origin with semi-axes (rx, ry, rz)."""
    t = np.linspace(0.0, np.pi, n_lat + 1)
    profile = np.stack([np.sin(t), np.cos(t) * rz], axis=1)
    profile[0, 0] = profile[-1, 0] = 0.0
    return _surface_of_revolution(profile, n_sides, rx, ry)


def _dome(rx: float, ry: float, rz: float, n_sides: int, n_lat: int) -> tuple[np.ndarray, np.ndarray]:
    """The upper half of an ellipsoid, closed by a flat disc at z=0."""
    t = np.linspace(0.0, np.pi / 2, n_lat + 1)
    profile = np.stack([np.sin(t), np.cos(t) * rz], axis=1)
    profile[0, 0] = 0.0
    profile = np.concatenate([profile, [[0.0, 0.0]]])
    return _surface_of_revolution(profile, n_sides, rx, ry)


def _frustum(r_bottom: tuple[float, float], r_top: tuple[float, float], z0: float, z1: float,
             n_sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed elliptic frustum from z0 (semi-axes r_bottom) up to z1 (semi-axes r_top)."""
    # revolve a unit profile, then scale each ring's ellipse separately
    profile = np.array([(0.0, z1), (1.0, z1), (1.0, z0), (0.0, z0)])
    v, f = _surface_of_revolution(profile, n_sides)
    top = np.isclose(v[:, 2], z1)
    v[top, 0] *= r_top[0]
    v[top, 1] *= r_top[1]
    v[~top, 0] *= r_bottom[0]
    v[~top, 1] *= r_bottom[1]
    return v, f


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return v, f


# ---------------------------------------------------------------------------------------
# Template body (height 1; every length below is a fraction of the standing height)

SKIN, SHIRT, TROUSERS, SHOES, HAIR = range(5)

_HIP_Z = 0.53            # hip joint height when standing
_HIP_Y = 0.052           # lateral offset of each hip joint
_THIGH = 0.245
_SHIN = 0.245
_ANKLE_Z = _HIP_Z - _THIGH - _SHIN          # 0.04: height of the ankle above the sole
_SHOULDER_Z = 0.805
_SHOULDER_Y = 0.125
_UPPER_ARM = 0.165
_FOREARM = 0.19           # forearm and hand together
_HEAD_RZ = 0.062
_HEAD_Z = 1.0 - _HEAD_RZ - 0.004           # the hair dome reaches height 1
_STRIDE_PER_HEIGHT = 0.6  # stride (two steps) length as a fraction of height

# segment ids; limbs are (left, right) pairs
_TORSO, _PELVIS, _NECK, _HEAD, _HAIR = 0, 1, 2, 3, 4
_UARM_L, _UARM_R, _FARM_L, _FARM_R = 5, 6, 7, 8
_THIGH_L, _THIGH_R, _SHIN_L, _SHIN_R, _FOOT_L, _FOOT_R = 9, 10, 11, 12, 13, 14
_N_SEG = 15


def _hair() -> tuple[np.ndarray, np.ndarray]:
    """A dome over the top and back of the head (in the head's joint frame), reaching height 1."""
    base_z = 0.012
    v, f = _dome(0.058, 0.050, 1.0 - _HEAD_Z - base_z, 8, 2)
    return v + np.array([-0.006, 0.0, base_z]), f


def _build_template() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Template vertices (V0, 3) in each segment's joint frame, faces (F0, 3), vertex segment ids (V0,), face materials (F0,)."""
    parts: list[tuple[int, int, tuple[np.ndarray, np.ndarray]]] = [
        (_TORSO, SHIRT, _frustum((0.055, 0.092), (0.062, 0.118), _HIP_Z + 0.03, _SHOULDER_Z + 0.025, 10)),
        (_PELVIS, TROUSERS, _frustum((0.058, 0.095), (0.055, 0.092), _HIP_Z - 0.045, _HIP_Z + 0.035, 10)),
        (_NECK, SKIN, _frustum((0.025, 0.027), (0.024, 0.026), _SHOULDER_Z + 0.01, _HEAD_Z - 0.03, 6)),
        (_HEAD, SKIN, _ellipsoid(0.054, 0.046, _HEAD_RZ, 8, 5)),
        (_HAIR, HAIR, _hair()),
    ]
    for seg in (_UARM_L, _UARM_R):
        parts.append((seg, SHIRT, _capsule(0.024, _UPPER_ARM, 5)))
    for seg in (_FARM_L, _FARM_R):
        parts.append((seg, SKIN, _capsule(0.02, _FOREARM - 0.02, 5)))
    for seg in (_THIGH_L, _THIGH_R):
        parts.append((seg, TROUSERS, _capsule(0.036, _THIGH, 6)))
    for seg in (_SHIN_L, _SHIN_R):
        parts.append((seg, TROUSERS, _capsule(0.028, _SHIN, 6)))
    for seg in (_FOOT_L, _FOOT_R):
        # the ankle is the origin; the sole is at -_ANKLE_Z
        parts.append((seg, SHOES, _box((-0.035, -0.028, -_ANKLE_Z), (0.1, 0.028, 0.01))))
    verts, faces, seg_of_vertex, mat_of_face = [], [], [], []
    offset = 0
    for seg, mat, (v, f) in parts:
        verts.append(v)
        faces.append(f + offset)
        seg_of_vertex.append(np.full(len(v), seg))
        mat_of_face.append(np.full(len(f), mat))
        offset += len(v)
    return (np.concatenate(verts), np.concatenate(faces).astype(np.int32),
            np.concatenate(seg_of_vertex), np.concatenate(mat_of_face))


_TEMPLATE_V, _TEMPLATE_F, _VERT_SEG, _FACE_MAT = _build_template()
_TEMPLATE_V.flags.writeable = False
_TEMPLATE_F.flags.writeable = False
TRIANGLES_PER_PERSON = len(_TEMPLATE_F)
VERTICES_PER_PERSON = len(_TEMPLATE_V)


def stride_length_m(height_m: np.ndarray | float) -> np.ndarray | float:
    """Length of one stride (two steps, one gait cycle of 2 pi) for a person of this height."""
    return _STRIDE_PER_HEIGHT * height_m


def _segment_poses(gait_phase_rad: np.ndarray, speed_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per person and segment: pitch angle (P, S) about the lateral axis and joint position (P, S, 2) as (x, z).

    The pitch ``a`` maps a template point (x, z) to (x cos a - z sin a, x sin a + z cos a)
    relative to the joint, so a positive ``a`` swings a hanging limb forward.
    """
    p = len(gait_phase_rad)
    s = np.clip(speed_mps / 1.0, 0.0, 1.0)            # gait amplitude: 0 standing, full at >= 1 m/s
    hip_amp = 0.46 * s
    knee_amp = 0.7 * s
    arm_amp = 0.40 * s
    elbow = 0.12 * s
    phi = gait_phase_rad
    sin_phi = np.sin(phi)
    hip = np.stack([hip_amp * sin_phi, -hip_amp * sin_phi], axis=1)                     # (P, 2) left, right
    # knees flex mostly while the leg swings forward (hip angle rising)
    knee = knee_amp[:, None] * np.maximum(0.0, np.stack([np.cos(phi + 0.6), np.cos(phi + np.pi + 0.6)], axis=1)) ** 1.5
    knee = knee + 0.08 * s[:, None]
    shoulder = np.stack([-arm_amp * sin_phi, arm_amp * sin_phi], axis=1)
    elbow_a = shoulder + elbow[:, None] * (1.0 + 0.8 * np.maximum(shoulder, 0.0) / np.maximum(arm_amp, 1e-9)[:, None])

    angle = np.zeros((p, _N_SEG))
    joint = np.zeros((p, _N_SEG, 2))
    angle[:, [_THIGH_L, _THIGH_R]] = hip
    angle[:, [_SHIN_L, _SHIN_R]] = hip - knee
    angle[:, [_UARM_L, _UARM_R]] = shoulder
    angle[:, [_FARM_L, _FARM_R]] = elbow_a
    joint[:, [_THIGH_L, _THIGH_R], 1] = _HIP_Z
    knee_x = _THIGH * np.sin(hip)
    knee_z = _HIP_Z - _THIGH * np.cos(hip)
    joint[:, [_SHIN_L, _SHIN_R], 0] = knee_x
    joint[:, [_SHIN_L, _SHIN_R], 1] = knee_z
    ankle_x = knee_x + _SHIN * np.sin(hip - knee)
    ankle_z = knee_z - _SHIN * np.cos(hip - knee)
    joint[:, [_FOOT_L, _FOOT_R], 0] = ankle_x           # feet stay level (angle 0)
    joint[:, [_FOOT_L, _FOOT_R], 1] = ankle_z
    joint[:, [_UARM_L, _UARM_R], 1] = _SHOULDER_Z
    joint[:, [_FARM_L, _FARM_R], 0] = _UPPER_ARM * np.sin(shoulder)
    joint[:, [_FARM_L, _FARM_R], 1] = _SHOULDER_Z - _UPPER_ARM * np.cos(shoulder)
    joint[:, [_HEAD, _HAIR], 1] = _HEAD_Z
    # lift the body so that the lower sole touches the floor: sole z = ankle z - _ANKLE_Z
    lift = _ANKLE_Z - ankle_z.min(axis=1)
    joint[:, :, 1] += lift[:, None]
    return angle, joint


_SEG_Y = np.zeros(_N_SEG)
_SEG_Y[[_UARM_L, _FARM_L]] = _SHOULDER_Y
_SEG_Y[[_UARM_R, _FARM_R]] = -_SHOULDER_Y
_SEG_Y[[_THIGH_L, _SHIN_L, _FOOT_L]] = _HIP_Y
_SEG_Y[[_THIGH_R, _SHIN_R, _FOOT_R]] = -_HIP_Y


def people_mesh(looks: list[HumanLook] | tuple[HumanLook, ...], xy_m: np.ndarray, heading_rad: np.ndarray,
                gait_phase_rad: np.ndarray, speed_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One triangle mesh of all people, posed for their gait phase and speed.

    Args:
        looks: P looks (height and colours).
        xy_m: float (P, 2) floor positions in world metres.
        heading_rad: float (P,) facing directions (0 = +x, counter-clockwise).
        gait_phase_rad: float (P,) gait phases; any real value, 2 pi per stride.
        speed_mps: float (P,) walking speeds; limb swing grows with speed, 0 gives straight limbs.

    Returns:
        vertices float32 (P * VERTICES_PER_PERSON, 3) in world metres (Z up, feet at z=0),
        faces int32 (P * TRIANGLES_PER_PERSON, 3) wound counter-clockwise seen from outside,
        face_colors uint8 (P * TRIANGLES_PER_PERSON, 3).
    """
    p = len(looks)
    xy_m = np.asarray(xy_m, dtype=np.float64)
    heading_rad = np.asarray(heading_rad, dtype=np.float64)
    gait_phase_rad = np.asarray(gait_phase_rad, dtype=np.float64)
    speed_mps = np.asarray(speed_mps, dtype=np.float64)
    assert xy_m.shape == (p, 2), xy_m.shape
    assert heading_rad.shape == (p,) and gait_phase_rad.shape == (p,) and speed_mps.shape == (p,)
    if p == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.uint8)

    height = np.array([lk.height_m for lk in looks])
    angle, joint = _segment_poses(gait_phase_rad, speed_mps)
    a = angle[:, _VERT_SEG]                              # (P, V0)
    ca, sa = np.cos(a), np.sin(a)
    tx, tz = _TEMPLATE_V[:, 0], _TEMPLATE_V[:, 2]
    bx = tx * ca - tz * sa + joint[:, _VERT_SEG, 0]      # body frame, height 1
    bz = tx * sa + tz * ca + joint[:, _VERT_SEG, 1]
    by = _TEMPLATE_V[:, 1] + _SEG_Y[_VERT_SEG]
    h = height[:, None]
    ch, sh = np.cos(heading_rad)[:, None], np.sin(heading_rad)[:, None]
    verts = np.empty((p, len(_TEMPLATE_V), 3), dtype=np.float32)
    verts[..., 0] = h * (ch * bx - sh * by) + xy_m[:, 0:1]
    verts[..., 1] = h * (sh * bx + ch * by) + xy_m[:, 1:2]
    verts[..., 2] = h * bz
    faces = (_TEMPLATE_F[None] + (np.arange(p, dtype=np.int32) * len(_TEMPLATE_V))[:, None, None]).reshape(-1, 3)
    palette = np.stack([lk.palette() for lk in looks])  # (P, 5, 3)
    colors = palette[:, _FACE_MAT].reshape(-1, 3)
    return verts.reshape(-1, 3), faces, colors
