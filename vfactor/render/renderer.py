"""Rasterising vehicles, occluders and the road with OpenGL (moderngl, headless EGL).

Conventions (docs/conventions.md): world z up, the road is ``z = 0``; cameras are
:class:`vfactor.camera.Camera` (OpenCV frame, pixel origin at the centre of the
top-left pixel). The OpenGL projection is built from ``K`` exactly, so a world
point projected with ``Camera.project`` lands on the pixel where it is drawn:

``x_ndc = 2 (u + 0.5) / W - 1``, ``y_ndc = 2 (v + 0.5) / H - 1`` (row ``v = 0``
is the first row read back, so no flip), ``w_clip = Z`` (the camera z), depth
from ``near`` to ``far``. Supersampling (default 2x2) renders at ``ss`` times
the size with the same normalised projection and averages blocks, which keeps
the pixel-centre convention.

Lens distortion: when the camera has distortion and ``distort=True`` (the
default), a pinhole image is rendered on a canvas padded to cover the
distorted field of view and remapped with ``cv2.remap`` (bilinear for the
image, nearest for depth and labels). With ``distort=False`` distortion is
ignored (the image is the pinhole image of ``K``).

Shading: Lambert (sun, directional) + ambient (sky), in linear light with sRGB
output; a little Blinn-Phong specular on paint, glass and lights; lights may
glow (emission). Optional sun shadows (a shadow map) and a soft contact shadow
under each vehicle on the road.

moderngl is imported lazily: ``import vfactor`` never needs it or a GPU.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import lru_cache

import gtsam
import numpy as np

from vfactor.camera import Camera
from vfactor.keypoints import NUM_KEYPOINTS
from vfactor.render.mesh import Appearance, Mesh, Part, vehicle_mesh
from vfactor.wireframe import Wireframe

__all__ = [
    "RenderingUnavailable",
    "Light",
    "Ground",
    "VehicleInstance",
    "VehicleAnnotation",
    "RenderResult",
    "Renderer",
    "get_context",
    "opengl_projection",
    "keypoint_annotations",
    "segments_blocked",
    "road_texture",
    "OCCLUDER_ID",
    "NO_VEHICLE",
]

#: ``vehicle_ids`` value of pixels showing the road, the sky or nothing.
NO_VEHICLE = -1
#: ``vehicle_ids`` value of pixels showing an occluder object (not a vehicle).
OCCLUDER_ID = -2
_MAX_FOOTPRINTS = 16
_FLOATS_PER_VERTEX = 14  # pos 3, normal 3, colour 3, (part, object, specular, emission) 4, texture 1


class RenderingUnavailable(RuntimeError):
    """moderngl or a headless OpenGL (EGL) context is not available."""


# --------------------------------------------------------------------------- context
_CONTEXT = None
_CONTEXT_PID = None


def get_context():
    """The process's shared headless moderngl context (EGL; created on first use, again after a fork).

    Raises:
        RenderingUnavailable: moderngl is not installed or no EGL/OpenGL 3.3 context can be made;
            the message says what to install.
    """
    global _CONTEXT, _CONTEXT_PID
    if _CONTEXT is not None and _CONTEXT_PID == os.getpid():
        return _CONTEXT
    try:
        import moderngl
    except ImportError as exc:
        raise RenderingUnavailable(
            "rendering needs moderngl: pip install 'vfactor[render]' (or pip install moderngl)"
        ) from exc
    errors = []
    for kwargs in ({"backend": "egl"}, {}):
        try:
            ctx = moderngl.create_standalone_context(require=330, **kwargs)
            break
        except Exception as exc:  # noqa: BLE001 - glcontext raises plain Exceptions
            errors.append(f"{kwargs.get('backend', 'default')}: {exc}")
    else:
        raise RenderingUnavailable(
            "no headless OpenGL 3.3 context: rendering uses EGL. On Debian/Ubuntu install "
            "libegl1 and Mesa (apt-get install libegl1 libgl1-mesa-dri; Mesa's llvmpipe renders on the CPU), "
            "or run where a GPU driver provides EGL. Tried: " + "; ".join(errors)
        )
    _CONTEXT, _CONTEXT_PID = ctx, os.getpid()
    return ctx


# --------------------------------------------------------------------------- scene description
@dataclass(frozen=True)
class Light:
    """Sun and sky.

    Attributes:
        direction: world direction *towards* the sun (normalised on use); z > 0 is above the horizon.
        color: sun colour (sRGB-ish multiplier).
        diffuse: sun intensity.
        ambient: sky (ambient) intensity.
        sky: sky colour: tints the ambient light, glass reflections and the empty background.
        shadows: draw sun shadows (a shadow map).
        shadow_strength: fraction of the sunlight removed in shadow.
        contact_shadow: darkening of the road right under a vehicle (0..1).
    """

    direction: tuple = (0.35, -0.25, 0.9)
    color: tuple = (1.0, 0.97, 0.92)
    diffuse: float = 0.8
    ambient: float = 0.45
    sky: tuple = (0.72, 0.8, 0.9)
    shadows: bool = True
    shadow_strength: float = 0.85
    contact_shadow: float = 0.6

    @property
    def unit_direction(self) -> np.ndarray:
        d = np.asarray(self.direction, float)
        return d / np.linalg.norm(d)


@dataclass(frozen=True)
class Ground:
    """The road plane ``z = 0``.

    Attributes:
        texture: (h, w, 3) uint8 RGB image tiled over the road, or ``None`` for :func:`road_texture`'s default.
        tile: metres covered by one copy of the texture along its width (its height scales alike).
        origin: (x, y) world point of the texture's corner; ``yaw``: its rotation (rad).
        extent: half size of the drawn road square, metres (around the camera's foot point).
        tint: per-channel multiplier of the texture's colours.
    """

    texture: np.ndarray | None = None
    tile: float = 12.0
    origin: tuple = (0.0, 0.0)
    yaw: float = 0.0
    extent: float = 800.0
    tint: tuple = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class VehicleInstance:
    """A vehicle to draw: shape, pose, looks.

    Attributes:
        wireframe: body-frame keypoints, metres.
        world_T_vehicle: pose (body -> world).
        appearance: colours and details (default :class:`Appearance`).
        wheel_radius: hub height above the road; ``None``: the hubs' mean world z (the road is z = 0).
        roof: the roof's height above the hubs, metres (:func:`vfactor.render.mesh.vehicle_mesh`); ``None``:
            at the window tops.
    """

    wireframe: Wireframe
    world_T_vehicle: gtsam.Pose3
    appearance: Appearance | None = None
    wheel_radius: float | None = None
    roof: float | None = None

    @classmethod
    def coerce(cls, item) -> "VehicleInstance":
        if isinstance(item, VehicleInstance):
            return item
        if isinstance(item, (tuple, list)) and 2 <= len(item) <= 5:
            return cls(*item)
        raise TypeError(
            "vehicles: expected VehicleInstance or (Wireframe, gtsam.Pose3[, Appearance[, wheel_radius[, roof]]]), "
            f"got {type(item).__name__}"
        )

    def resolved_wheel_radius(self) -> float:
        if self.wheel_radius is not None:
            return float(self.wheel_radius)
        hubs = self.wireframe.in_world(self.world_T_vehicle)[:4]
        r = float(hubs[:, 2].mean())
        if not 0.1 <= r <= 1.5:
            raise ValueError(
                f"wheel_radius: the hubs stand {r:.3f} m above the road z = 0; give wheel_radius explicitly "
                "or place the vehicle on the road (e.g. vfactor.sim.road_pose)"
            )
        return r

    def body_mesh(self) -> Mesh:
        return _cached_vehicle_mesh(self.wireframe, self.appearance, self.resolved_wheel_radius(), self.roof)


@lru_cache(maxsize=64)
def _cached_vehicle_mesh(wireframe: Wireframe, appearance: Appearance | None, wheel_radius: float,
                         roof: float | None = None) -> Mesh:
    return vehicle_mesh(wireframe, appearance, wheel_radius, roof)


@dataclass
class VehicleAnnotation:
    """The 12 keypoints of one vehicle in one rendered image.

    Attributes:
        uv: (12, 2) pixels from ``Camera.project`` (with the camera's distortion).
        depth: (12,) camera z, metres.
        in_image: (12,) inside the image and in front of the camera.
        self_occluded: (12,) hidden by the vehicle's own body (exact ray test against its mesh).
        occluded_by_other: (12,) hidden by another vehicle or an occluder object.
        box: (4,) amodal box ``(x0, y0, x1, y1)`` of the whole vehicle mesh, image pixel edges
            (the convention of ``vfactor.heatmaps`` ROIs); NaN when part of it is behind the camera.
    """

    uv: np.ndarray
    depth: np.ndarray
    in_image: np.ndarray
    self_occluded: np.ndarray
    occluded_by_other: np.ndarray
    box: np.ndarray

    @property
    def visible(self) -> np.ndarray:
        """(12,) in the image and occluded by nothing."""
        return self.in_image & ~self.self_occluded & ~self.occluded_by_other


@dataclass
class RenderResult:
    """What :meth:`Renderer.render` returns.

    Attributes:
        image: (H, W, 3) uint8, **RGB** (use ``image[..., ::-1]`` for OpenCV's BGR).
        depth: (H, W) float32 camera z in metres of the nearest surface in each pixel
            (the nearest of its supersamples); ``inf`` where only sky is seen.
        vehicle_ids: (H, W) int16: index into ``vehicles`` of the nearest surface,
            :data:`NO_VEHICLE` (-1) for road/sky, :data:`OCCLUDER_ID` (-2) for occluder objects.
        part_ids: (H, W) uint8 :class:`vfactor.render.mesh.Part` of the nearest surface.
        annotations: one :class:`VehicleAnnotation` per vehicle, in the order given.
    """

    image: np.ndarray
    depth: np.ndarray
    vehicle_ids: np.ndarray
    part_ids: np.ndarray
    annotations: list = field(default_factory=list)


# --------------------------------------------------------------------------- maths
def opengl_projection(K, width: int, height: int, near: float, far: float) -> np.ndarray:
    """4x4 matrix from OpenCV camera coordinates to OpenGL clip coordinates for intrinsics ``K``.

    The pixel ``(u, v)`` (OpenCV: centre of the top-left pixel is (0, 0)) maps to
    ``x_ndc = 2 (u + 0.5) / W - 1`` and ``y_ndc = 2 (v + 0.5) / H - 1``; ``w_clip``
    is the camera z; depth maps ``[near, far]`` to ``[-1, 1]``.
    """
    K = np.asarray(K, float)
    fx, s, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    P = np.zeros((4, 4))
    P[0, 0], P[0, 1], P[0, 2] = 2 * fx / width, 2 * s / width, 2 * (cx + 0.5) / width - 1
    P[1, 1], P[1, 2] = 2 * fy / height, 2 * (cy + 0.5) / height - 1
    P[2, 2], P[2, 3] = (far + near) / (far - near), -2 * far * near / (far - near)
    P[3, 2] = 1.0
    return P


def segments_blocked(origin, targets, triangles, tail: float = 0.02) -> np.ndarray:
    """Whether the segments from ``origin`` to each target cross any triangle (exact, Moller-Trumbore).

    Args:
        origin: (3,) segment start (a camera centre).
        targets: (M, 3) segment ends.
        triangles: (T, 3, 3) triangles.
        tail: the last ``tail`` metres of each segment are ignored (a keypoint lies on its own surface).

    Returns:
        (M,) bool.
    """
    origin = np.asarray(origin, float)
    targets = np.asarray(targets, float).reshape(-1, 3)
    tri = np.asarray(triangles, float).reshape(-1, 3, 3)
    out = np.zeros(len(targets), dtype=bool)
    if len(tri) == 0 or len(targets) == 0:
        return out
    d = targets - origin  # (M, 3)
    length = np.linalg.norm(d, axis=1)
    t_max = 1.0 - tail / np.maximum(length, 1e-12)
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    s = origin - tri[:, 0]  # (T, 3)
    q = np.cross(s, e1)  # (T, 3)
    for start in range(0, len(tri), 4096):
        sl = slice(start, start + 4096)
        p = np.cross(d[:, None, :], e2[None, sl])  # (M, T, 3)
        det = np.einsum("mtk,tk->mt", p, e1[sl])
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            u = np.einsum("mtk,tk->mt", p, s[sl]) * inv
            v = np.einsum("mk,tk->mt", d, q[sl]) * inv
            t = np.einsum("tk,tk->t", e2[sl], q[sl])[None] * inv
        hit = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6) & (t < t_max[:, None])
        out |= hit.any(axis=1)
    return out


def road_texture(rng: np.random.Generator | None = None, size: int = 256, lanes: bool = True) -> np.ndarray:
    """A procedural asphalt texture (size x size RGB uint8): noise at a few scales, optional lane markings.

    Meant to be tiled by :class:`Ground` with ``tile`` metres per copy.
    """
    import cv2

    rng = np.random.default_rng(0) if rng is None else rng
    base = rng.uniform(0.28, 0.5)
    tint = rng.normal(0.0, 0.015, size=3)
    img = np.full((size, size), base, np.float32)
    for cells, amp in ((4, 0.02), (16, 0.02), (64, 0.025), (size, 0.035)):
        noise = rng.normal(0.0, 1.0, size=(cells, cells)).astype(np.float32)
        # Wrap so the texture tiles without seams.
        noise = np.pad(noise, 1, mode="wrap")
        up = cv2.resize(noise, (size + 2 * size // cells, size + 2 * size // cells), interpolation=cv2.INTER_CUBIC)
        o = size // cells
        img += amp * rng.uniform(0.5, 1.5) * up[o : o + size, o : o + size]
    rgb = np.clip(img[..., None] + tint, 0.0, 1.0)
    if rng.uniform() < 0.4:  # patches (repairs, stains)
        for _ in range(rng.integers(1, 4)):
            c = rng.integers(0, size, 2)
            axes = rng.integers(size // 16, size // 5, 2)
            shade = rng.uniform(-0.1, 0.08)
            mask = np.zeros((size, size), np.uint8)
            angle = float(rng.uniform(0, 180))
            cv2.ellipse(mask, (int(c[0]), int(c[1])), (int(axes[0]), int(axes[1])), angle, 0, 360, 1, -1)
            rgb += shade * mask[..., None]
    if lanes:
        paint = np.array([0.9, 0.9, 0.88]) if rng.uniform() < 0.8 else np.array([0.9, 0.75, 0.2])
        width = max(1, int(size * rng.uniform(0.008, 0.02)))
        dashed = rng.uniform() < 0.6
        for x in rng.choice([size // 4, size // 2, 3 * size // 4], size=rng.integers(1, 3), replace=False):
            x = int(x)
            if dashed:
                for y0 in range(0, size, size // 4):
                    dash = rgb[y0 : y0 + size // 8, x : x + width]
                    dash[:] = 0.8 * paint + 0.2 * dash
            else:
                rgb[:, x : x + width] = 0.8 * paint + 0.2 * rgb[:, x : x + width]
    return (np.clip(rgb, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


# --------------------------------------------------------------------------- shaders
_VERTEX = """
#version 330
uniform mat4 u_view;
uniform mat4 u_proj;
uniform mat4 u_light_vp;
in vec3 in_pos;
in vec3 in_normal;
in vec3 in_color;
in vec4 in_mat;
in float in_tex;
out vec3 v_pos;
out vec3 v_normal;
out vec3 v_color;
flat out vec4 v_mat;
out float v_tex;
out float v_z;
out vec4 v_lpos;
void main() {
    vec4 pc = u_view * vec4(in_pos, 1.0);
    gl_Position = u_proj * pc;
    v_z = pc.z;
    v_pos = in_pos;
    v_normal = in_normal;
    v_color = in_color;
    v_mat = in_mat;
    v_tex = in_tex;
    v_lpos = u_light_vp * vec4(in_pos, 1.0);
}
"""

_FRAGMENT = """
#version 330
uniform vec3 u_cam;
uniform vec3 u_light_dir;
uniform vec3 u_light_color;
uniform vec3 u_sky;
uniform float u_ambient;
uniform float u_diffuse;
uniform float u_shadow_strength;
uniform float u_contact;
uniform int u_use_shadow;
uniform float u_shadow_bias;
uniform float u_shadow_texel;
uniform sampler2DShadow u_shadow;
uniform sampler2D u_ground;
uniform sampler3D u_noise;
uniform vec4 u_ground_xf;      // cos(yaw), sin(yaw), 1/tile_u, 1/tile_v
uniform vec2 u_ground_origin;
uniform vec3 u_ground_tint;
uniform float u_seed;
uniform int u_n_fp;
uniform vec4 u_fp[16];         // centre x, y, cos(yaw), sin(yaw)
uniform vec2 u_fp_half[16];    // half length, half width
in vec3 v_pos;
in vec3 v_normal;
in vec3 v_color;
flat in vec4 v_mat;
in float v_tex;
in float v_z;
in vec4 v_lpos;
layout(location = 0) out vec4 f_color;
layout(location = 1) out vec4 f_data;

vec3 to_linear(vec3 c) { return pow(max(c, vec3(0.0)), vec3(2.2)); }
vec3 to_srgb(vec3 c) { return pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2)); }

void main() {
    int part = int(v_mat.x + 0.5);
    vec3 n = normalize(v_normal);
    vec3 V = normalize(u_cam - v_pos);
    if (dot(n, V) < 0.0) n = -n;
    vec3 albedo;
    float ao = 1.0;
    if (part == 1 || part == 13) {
        for (int k = 0; k < u_n_fp; k++) {
            vec2 d = v_pos.xy - u_fp[k].xy;
            vec2 local = vec2(dot(d, u_fp[k].zw), dot(d, vec2(-u_fp[k].w, u_fp[k].z)));
            vec2 out_d = max(abs(local) - u_fp_half[k], vec2(0.0));
            ao *= 1.0 - u_contact * exp(-length(out_d) / 0.25);
        }
    }
    if (part == 1) {
        vec2 q = v_pos.xy - u_ground_origin;
        vec2 uv = vec2(dot(q, u_ground_xf.xy), dot(q, vec2(-u_ground_xf.y, u_ground_xf.x))) * u_ground_xf.zw;
        albedo = to_linear(texture(u_ground, uv).rgb * u_ground_tint);
    } else {
        albedo = to_linear(v_color);
        if (v_tex > 0.0) {
            float nz = texture(u_noise, v_pos * 0.5 + u_seed).r * 0.6 + texture(u_noise, v_pos * 2.1 + u_seed).r * 0.4;
            albedo *= 1.0 + v_tex * (2.0 * nz - 1.0) * 2.0;
        }
    }
    float sh = 1.0;
    if (u_use_shadow == 1) {
        vec3 lp = v_lpos.xyz / v_lpos.w * 0.5 + 0.5;
        if (lp.x > 0.0 && lp.x < 1.0 && lp.y > 0.0 && lp.y < 1.0 && lp.z < 1.0) {
            float acc = 0.0;
            for (int i = 0; i < 4; i++) {
                vec2 o = vec2((i & 1) == 0 ? -0.7 : 0.7, (i & 2) == 0 ? -0.7 : 0.7) * u_shadow_texel;
                acc += texture(u_shadow, vec3(lp.xy + o, lp.z - u_shadow_bias));
            }
            sh = 0.25 * acc;
        }
    }
    float lit = mix(1.0, sh, u_shadow_strength);
    vec3 L = normalize(u_light_dir);
    float lambert = max(dot(n, L), 0.0);
    vec3 sky = to_linear(u_sky);
    vec3 sun = to_linear(u_light_color);
    vec3 col = albedo * (u_ambient * ao * sky * (0.75 + 0.25 * n.z) + u_diffuse * lambert * lit * ao * sun);
    float spec_strength = v_mat.z;
    if (spec_strength > 0.0) {
        vec3 H = normalize(L + V);
        float shininess = (part == 4) ? 80.0 : 30.0;
        col += spec_strength * pow(max(dot(n, H), 0.0), shininess) * u_diffuse * lit * sun;
        float fresnel = pow(1.0 - max(dot(n, V), 0.0), 4.0);
        col += spec_strength * ((part == 4) ? 0.35 : 0.12) * (0.15 + fresnel) * sky * u_ambient;
    }
    col += albedo * v_mat.w;
    f_color = vec4(to_srgb(col), 1.0);
    f_data = vec4(v_z, v_mat.y, float(part), 1.0);
}
"""

_SHADOW_VERTEX = """
#version 330
uniform mat4 u_light_vp;
in vec3 in_pos;
void main() { gl_Position = u_light_vp * vec4(in_pos, 1.0); }
"""

_SHADOW_FRAGMENT = """
#version 330
void main() { }
"""


# --------------------------------------------------------------------------- renderer
class Renderer:
    """Draws vehicles (low-poly meshes around their wireframes), occluders and the road for a camera.

    Args:
        width, height: output image size in pixels (the camera's ``image_size`` must match when set).
        supersample: render at this many times the size per axis and average (anti-aliasing; 1 disables;
            fractions such as 1.5 work too: the canvas is resized with area averaging).
        near, far: clipping distances, metres.
        shadow_map_size: texels per side of the sun's shadow map.

    Raises:
        RenderingUnavailable: moderngl or an EGL context is missing (see :func:`get_context`).
    """

    def __init__(self, width: int, height: int, supersample: float = 2, near: float = 0.5, far: float = 2000.0,
                 shadow_map_size: int = 1024):
        if int(width) <= 0 or int(height) <= 0:
            raise ValueError(f"width, height: expected positive integers, got {width}, {height}")
        if not float(supersample) >= 1.0:
            raise ValueError(f"supersample: expected a number >= 1, got {supersample}")
        self.width, self.height = int(width), int(height)
        self.supersample = float(supersample)
        self.near, self.far = float(near), float(far)
        self.ctx = ctx = get_context()
        self._prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._shadow_prog = ctx.program(vertex_shader=_SHADOW_VERTEX, fragment_shader=_SHADOW_FRAGMENT)
        self._vbo = None
        self._vao = self._shadow_vao = None
        self._fbos: dict = {}
        self._shadow_size = int(shadow_map_size)
        self._shadow_tex = ctx.depth_texture((self._shadow_size, self._shadow_size))
        self._shadow_tex.compare_func = "<="
        self._shadow_tex.repeat_x = self._shadow_tex.repeat_y = False
        self._shadow_fbo = ctx.framebuffer(depth_attachment=self._shadow_tex)
        self._ground_cache: dict = {}
        _set(self._prog, "u_shadow", 0)
        _set(self._prog, "u_ground", 1)
        _set(self._prog, "u_noise", 2)
        noise = np.random.default_rng(7).integers(0, 256, size=(32, 32, 32), dtype=np.uint8)
        self._noise_tex = ctx.texture3d((32, 32, 32), 1, noise.tobytes(), alignment=1)
        self._noise_tex.repeat_x = self._noise_tex.repeat_y = self._noise_tex.repeat_z = True

    # ---------------------------------------------------------------- public
    def render(
        self,
        camera: Camera,
        vehicles=(),
        background: np.ndarray | None = None,
        light: Light | None = None,
        occluders=(),
        ground: Ground | bool | None = True,
        distort: bool = True,
        texture_seed: float = 0.0,
        annotate: bool = True,
    ) -> RenderResult:
        """Renders a scene and annotates every vehicle's keypoints.

        Args:
            camera: the camera (``K``, distortion, ``world_T_camera``).
            vehicles: :class:`VehicleInstance` items or tuples ``(Wireframe, gtsam.Pose3
                world_T_vehicle[, Appearance[, wheel_radius]])``.
            background: (H, W, 3) uint8 RGB shown where nothing is drawn (the sky above
                the road's horizon, or everywhere with ``ground=False``); ``None``: the sky colour.
            light: sun and sky (default :class:`Light`).
            occluders: extra :class:`Mesh` objects in the world frame (poles, boxes, signs).
            ground: ``True`` (default road texture), a :class:`Ground`, or ``False``/``None`` (no road).
            distort: apply the camera's lens distortion (by remapping) when it has some.
            texture_seed: offset of the procedural surface noise.
            annotate: compute the keypoint annotations (exact ray tests; an empty list otherwise).

        Returns:
            :class:`RenderResult` (image RGB uint8, depth, vehicle ids, part ids, annotations).
        """
        W, H = self.width, self.height
        if camera.image_size is not None and tuple(camera.image_size) != (W, H):
            raise ValueError(f"camera.image_size {camera.image_size} differs from the renderer's size {(W, H)}")
        light = Light() if light is None else light
        if background is not None:
            background = np.asarray(background)
            if background.shape != (H, W, 3) or background.dtype != np.uint8:
                raise ValueError(f"background: expected ({H}, {W}, 3) uint8, got {background.shape} {background.dtype}")
        instances = [VehicleInstance.coerce(v) for v in vehicles]
        body = [inst.body_mesh() for inst in instances]
        world = [m.transformed(inst.world_T_vehicle) for m, inst in zip(body, instances)]
        occluders = [o for o in occluders if o is not None and len(o)]
        annotations = keypoint_annotations(camera, instances, world, occluders) if annotate else []

        if distort and camera.has_distortion:
            image, data = self._render_distorted(camera, instances, world, occluders, light, ground, texture_seed)
        else:
            image, data = self._render_pinhole(camera.K, camera.world_T_camera, (W, H), instances, world, occluders,
                                               light, ground, texture_seed)
        return self._finish(image, data, background, light, annotations)

    # ---------------------------------------------------------------- internals
    def _fbo(self, size):
        fbo = self._fbos.get(size)
        if fbo is None:
            ctx = self.ctx
            color = ctx.texture(size, 4, dtype="f1")
            data = ctx.texture(size, 4, dtype="f4")
            depth = ctx.depth_renderbuffer(size)
            fbo = ctx.framebuffer(color_attachments=[color, data], depth_attachment=depth)
            if len(self._fbos) > 8:
                for old in self._fbos.values():
                    old.release()
                self._fbos.clear()
            self._fbos[size] = fbo
        return fbo

    def _upload(self, meshes, ids, textures):
        verts = []
        for mesh, obj, tex in zip(meshes, ids, textures):
            n = len(mesh)
            if n == 0:
                continue
            normals = np.repeat(mesh.face_normals(), 3, axis=0)
            arr = np.empty((n * 3, _FLOATS_PER_VERTEX), np.float32)
            arr[:, 0:3] = mesh.vertices
            arr[:, 3:6] = normals
            arr[:, 6:9] = np.repeat(mesh.colors, 3, axis=0)
            arr[:, 9] = np.repeat(mesh.parts, 3)
            arr[:, 10] = obj
            arr[:, 11] = np.repeat(mesh.specular, 3)
            arr[:, 12] = np.repeat(mesh.emission, 3)
            arr[:, 13] = 0.0 if mesh.parts[0] == Part.GROUND else tex
            verts.append(arr)
        data = np.concatenate(verts) if verts else np.zeros((0, _FLOATS_PER_VERTEX), np.float32)
        nbytes = max(data.nbytes, 4 * _FLOATS_PER_VERTEX * 3)
        if self._vbo is None or self._vbo.size < nbytes:
            for obj in (self._vao, self._shadow_vao, self._vbo):
                if obj is not None:
                    obj.release()
            self._vbo = self.ctx.buffer(reserve=int(nbytes * 1.5))
            self._vao = self.ctx.vertex_array(
                self._prog, [(self._vbo, "3f 3f 3f 4f 1f", "in_pos", "in_normal", "in_color", "in_mat", "in_tex")]
            )
            self._shadow_vao = self.ctx.vertex_array(
                self._shadow_prog, [(self._vbo, f"3f {(_FLOATS_PER_VERTEX - 3) * 4}x", "in_pos")]
            )
        if data.nbytes:
            self._vbo.write(data.tobytes())
        return len(data)

    def _ground_texture(self, ground: Ground):
        src = _default_road() if ground.texture is None else ground.texture
        hit = self._ground_cache.get(id(src))
        if hit is not None and hit[0] is src:
            return hit[1]
        img = np.ascontiguousarray(np.asarray(src, np.uint8))
        if img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(f"ground.texture: expected (h, w, 3) uint8, got {img.shape}")
        if len(self._ground_cache) >= 64:
            for _, tex in self._ground_cache.values():
                tex.release()
            self._ground_cache.clear()
        tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), alignment=1)
        tex.build_mipmaps()
        tex.repeat_x = tex.repeat_y = True
        self._ground_cache[id(src)] = (src, tex)  # keeps src alive, so its id stays unique
        return tex

    def _render_pinhole(self, K, world_T_camera, size, instances, world, occluders, light, ground, texture_seed):
        ctx = self.ctx
        W, H = size
        size_ss = self._canvas(size)
        camera_T_world = np.linalg.inv(np.asarray(world_T_camera, float))
        cam_center = np.asarray(world_T_camera, float)[:3, 3]

        meshes, ids, texes = [], [], []
        for i, (m, inst) in enumerate(zip(world, instances)):
            meshes.append(m)
            ids.append(float(i))
            texes.append((inst.appearance or Appearance()).texture)
        for o in occluders:
            meshes.append(o)
            ids.append(float(OCCLUDER_ID))
            texes.append(0.03)
        n_casters = sum(len(m) for m in meshes) * 3
        use_ground = ground is not None and ground is not False
        if use_ground:
            g = Ground() if ground is True else ground
            e = g.extent
            c = cam_center[:2]
            corners = np.array([[c[0] - e, c[1] - e, 0], [c[0] + e, c[1] - e, 0], [c[0] + e, c[1] + e, 0],
                                [c[0] - e, c[1] + e, 0]])
            gm = Mesh(np.array([corners[[0, 1, 2]], corners[[0, 2, 3]]]), np.full((2, 3), 0.5), np.full(2, Part.GROUND),
                      np.zeros(2), np.zeros(2))
            meshes.append(gm)
            ids.append(float(NO_VEHICLE))
            texes.append(0.0)
        n_vertices = self._upload(meshes, ids, texes)

        prog = self._prog
        light_vp = np.eye(4)
        use_shadow = bool(light.shadows and n_casters > 0 and light.unit_direction[2] > 0.05)
        if use_shadow:
            light_vp = self._shadow_matrix(world + list(occluders), light.unit_direction)
            _write(self._shadow_prog, "u_light_vp", light_vp.T.astype("f4").tobytes())
            self._shadow_fbo.use()
            self._shadow_fbo.clear(depth=1.0)
            ctx.enable(ctx.DEPTH_TEST)
            ctx.polygon_offset = (2.0, 4.0)
            self._shadow_vao.render(vertices=n_casters)
            ctx.polygon_offset = (0.0, 0.0)
        fbo = self._fbo(size_ss)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        ctx.disable(ctx.CULL_FACE)
        _write(prog, "u_view", camera_T_world.T.astype("f4").tobytes())
        _write(prog, "u_proj", opengl_projection(K, W, H, self.near, self.far).T.astype("f4").tobytes())
        _write(prog, "u_light_vp", light_vp.T.astype("f4").tobytes())
        _set(prog, "u_cam", tuple(cam_center))
        _set(prog, "u_light_dir", tuple(light.unit_direction))
        _set(prog, "u_light_color", tuple(light.color))
        _set(prog, "u_sky", tuple(light.sky))
        _set(prog, "u_ambient", float(light.ambient))
        _set(prog, "u_diffuse", float(light.diffuse))
        _set(prog, "u_shadow_strength", float(light.shadow_strength))
        _set(prog, "u_contact", float(light.contact_shadow))
        _set(prog, "u_use_shadow", int(use_shadow))
        _set(prog, "u_shadow_bias", 0.0015)
        _set(prog, "u_shadow_texel", 1.0 / self._shadow_size)
        _set(prog, "u_seed", float(texture_seed))
        fps = np.zeros((_MAX_FOOTPRINTS, 4), np.float32)
        halves = np.zeros((_MAX_FOOTPRINTS, 2), np.float32)
        n_fp = 0
        for m, inst in zip(world, instances):
            if n_fp == _MAX_FOOTPRINTS:
                break
            p = inst.wireframe.vehicle_p_keypoints
            T = inst.world_T_vehicle.matrix()
            ctr = T[:3, :3] @ np.array([0.5 * (p[:, 0].max() + p[:, 0].min()), 0.0, 0.0]) + T[:3, 3]
            yaw = np.arctan2(T[1, 0], T[0, 0])
            fps[n_fp] = (ctr[0], ctr[1], np.cos(yaw), np.sin(yaw))
            halves[n_fp] = (0.5 * (p[:, 0].max() - p[:, 0].min()) - 0.1, np.abs(p[:4, 1]).max() - 0.1)
            n_fp += 1
        _set(prog, "u_n_fp", n_fp)
        _write(prog, "u_fp", fps.tobytes())
        _write(prog, "u_fp_half", halves.tobytes())
        self._shadow_tex.use(location=0)
        self._noise_tex.use(location=2)
        if use_ground:
            tex = self._ground_texture(g)
            tex.use(location=1)
            h_img, w_img = tex.size[1], tex.size[0]
            _set(prog, "u_ground_xf", (np.cos(g.yaw), np.sin(g.yaw), 1.0 / g.tile, w_img / (h_img * g.tile)))
            _set(prog, "u_ground_origin", tuple(float(v) for v in g.origin))
            _set(prog, "u_ground_tint", tuple(float(v) for v in g.tint))
        else:
            _set(prog, "u_ground_xf", (1.0, 0.0, 1.0, 1.0))
            _set(prog, "u_ground_origin", (0.0, 0.0))
        if n_vertices:
            self._vao.render(vertices=n_vertices)
        color = np.frombuffer(fbo.read(components=4, attachment=0), np.uint8).reshape(size_ss[1], size_ss[0], 4)
        data = np.frombuffer(fbo.read(components=4, attachment=1, dtype="f4"), np.float32).reshape(
            size_ss[1], size_ss[0], 4)
        return color, data

    def _shadow_matrix(self, meshes, L):
        pts = np.concatenate([m.vertices for m in meshes])
        center = np.array([*pts[:, :2].mean(0), 0.0])
        radius = float(min(np.linalg.norm(pts[:, :2] - center[:2], axis=1).max() + 1.0, 60.0))
        # Stretch to hold the shadows of tall things too.
        z_top = float(pts[:, 2].max())
        reach = z_top * np.linalg.norm(L[:2]) / max(L[2], 0.2)
        radius = min(radius + reach, 80.0)
        fwd = -L
        up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
        x = np.cross(fwd, up)
        x /= np.linalg.norm(x)
        y = np.cross(fwd, x)
        R = np.stack([x, y, fwd])
        view = np.eye(4)
        view[:3, :3] = R
        view[:3, 3] = -R @ center
        depth = 40.0
        ortho = np.diag([1.0 / radius, 1.0 / radius, 1.0 / depth, 1.0])
        return ortho @ view

    def _render_distorted(self, camera, instances, world, occluders, light, ground, texture_seed):
        import cv2

        W, H = self.width, self.height
        Wc, Hc = self._canvas((W, H))
        K = camera.K
        # Output canvas samples -> output pixels -> normalised pinhole coordinates -> ideal pixels of K.
        us = (np.arange(Wc) + 0.5) * W / Wc - 0.5
        vs = (np.arange(Hc) + 0.5) * H / Hc - 0.5
        uu, vv = np.meshgrid(us, vs)
        xy = camera.undistort_pixels(np.stack([uu, vv], -1).reshape(-1, 2))
        u_id = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
        v_id = K[1, 1] * xy[:, 1] + K[1, 2]
        pad_l = int(np.ceil(max(0.0, -u_id.min()))) + 2
        pad_t = int(np.ceil(max(0.0, -v_id.min()))) + 2
        pad_r = int(np.ceil(max(0.0, u_id.max() - (W - 1)))) + 2
        pad_b = int(np.ceil(max(0.0, v_id.max() - (H - 1)))) + 2
        Wp, Hp = W + pad_l + pad_r, H + pad_t + pad_b
        if Wp * Hp > 4 * W * H:
            raise ValueError("camera distortion too strong to render by remapping (canvas > 4x the image)")
        Kp = np.array(K, float)
        Kp[0, 2] += pad_l
        Kp[1, 2] += pad_t
        color, data = self._render_pinhole(Kp, camera.world_T_camera, (Wp, Hp), instances, world, occluders, light,
                                           ground, texture_seed)
        Wpc, Hpc = self._canvas((Wp, Hp))
        map_x = ((u_id + pad_l + 0.5) * Wpc / Wp - 0.5).reshape(Hc, Wc).astype(np.float32)
        map_y = ((v_id + pad_t + 0.5) * Hpc / Hp - 0.5).reshape(Hc, Wc).astype(np.float32)
        color = cv2.remap(color, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        data = cv2.remap(data, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        return color, data

    def _canvas(self, size) -> tuple[int, int]:
        """The supersampled canvas of an image size."""
        return (max(1, int(round(size[0] * self.supersample))), max(1, int(round(size[1] * self.supersample))))

    def _finish(self, color, data, background, light, annotations):
        import cv2

        H, W = self.height, self.width
        Hc, Wc = color.shape[:2]
        # The canvas is premultiplied (cleared to 0 with alpha 0): average, then put the background behind.
        small = cv2.resize(color, (W, H), interpolation=cv2.INTER_AREA) if (Wc, Hc) != (W, H) else color
        alpha = small[..., 3:4].astype(np.float32) / 255.0
        rgb = small[..., :3].astype(np.float32)
        if background is not None:
            bg = background.astype(np.float32)
        else:
            bg = np.asarray(light.sky, np.float32) * 255.0
        image = np.clip(rgb + bg * (1.0 - alpha) + 0.5, 0, 255).astype(np.uint8)
        hit = data[..., 3] > 0
        z = np.where(hit, data[..., 0], np.inf).astype(np.float32)
        obj = np.where(hit, data[..., 1], NO_VEHICLE)
        part = np.where(hit, data[..., 2], 0)
        label = np.rint(obj * 256 + part).astype(np.int32)  # object and part in one array
        if (Wc, Hc) == (W, H):
            depth = z
        elif Wc % W == 0 and Hc % H == 0:
            fx, fy = Wc // W, Hc // H
            zb = z.reshape(H, fy, W, fx).transpose(0, 2, 1, 3).reshape(H, W, fx * fy)
            pick = np.argmin(zb, axis=2)[..., None]
            depth = np.take_along_axis(zb, pick, 2)[..., 0]
            blocks = label.reshape(H, fy, W, fx).transpose(0, 2, 1, 3).reshape(H, W, fx * fy)
            label = np.take_along_axis(blocks, pick, 2)[..., 0]
        else:
            depth = cv2.resize(z, (W, H), interpolation=cv2.INTER_NEAREST)
            label = cv2.resize(label, (W, H), interpolation=cv2.INTER_NEAREST)
        obj = np.floor_divide(label + 128, 256).astype(np.int16)
        part = (label - 256 * obj).astype(np.uint8)
        return RenderResult(image, depth.astype(np.float32), obj, part, annotations)

    def release(self) -> None:
        """Frees this renderer's OpenGL objects (the shared context stays)."""
        for obj in [self._vao, self._shadow_vao, self._vbo, self._shadow_fbo, self._shadow_tex, self._noise_tex,
                    *(tex for _, tex in self._ground_cache.values()),
                    self._prog, self._shadow_prog, *self._fbos.values()]:
            if obj is not None:
                obj.release()
        self._fbos.clear()
        self._ground_cache.clear()
        self._vao = self._shadow_vao = self._vbo = None


def _set(prog, name, value) -> None:
    if name in prog:  # the GLSL compiler drops unused uniforms
        prog[name].value = value


def _write(prog, name, data: bytes) -> None:
    if name in prog:
        prog[name].write(data)


@lru_cache(maxsize=1)
def _default_road() -> np.ndarray:
    return road_texture(np.random.default_rng(12345), 256, lanes=False)


# --------------------------------------------------------------------------- annotations
def _may_block(origin, targets, mesh: Mesh) -> bool:
    """Whether a mesh's bounding sphere meets any segment origin -> target (a cheap pre-test)."""
    v = mesh.vertices
    lo, hi = v.min(0), v.max(0)
    c, r = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
    d = targets - origin
    t = np.clip(((c - origin) @ d.T) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-12), 0.0, 1.0)
    closest = origin + t[:, None] * d
    return bool(np.any(np.linalg.norm(closest - c, axis=1) <= r))


def keypoint_annotations(camera: Camera, vehicles, world_meshes=None, occluders=()) -> list[VehicleAnnotation]:
    """Pixels and occlusion flags of every vehicle's 12 keypoints (no rendering needed).

    Occlusion is an exact ray test: keypoint ``k`` of vehicle ``i`` is
    ``self_occluded`` when the segment from the camera centre to it crosses a
    triangle of vehicle ``i``'s own mesh (its last 2 cm ignored, as the
    keypoint lies on that mesh) and ``occluded_by_other`` when it crosses
    another vehicle's mesh or an occluder. The rendered depth agrees with this
    up to the pixel grid (see ``tests/render``).

    Args:
        camera: the camera.
        vehicles: :class:`VehicleInstance` items or tuples (see :meth:`Renderer.render`).
        world_meshes: the vehicles' meshes in the world frame (built when ``None``).
        occluders: world-frame :class:`Mesh` objects.
    """
    instances = [VehicleInstance.coerce(v) for v in vehicles]
    if world_meshes is None:
        world_meshes = [inst.body_mesh().transformed(inst.world_T_vehicle) for inst in instances]
    centre = camera.center
    size = camera.image_size
    out = []
    for i, inst in enumerate(instances):
        kp = inst.wireframe.in_world(inst.world_T_vehicle)
        uv, depth = camera.project(kp)
        in_front = depth > 1e-6
        in_image = in_front & camera.in_image(uv)
        self_occ = segments_blocked(centre, kp, world_meshes[i].triangles)
        others = [m for j, m in enumerate(world_meshes) if j != i] + list(occluders)
        others = [m.triangles for m in others if _may_block(centre, kp, m)]
        other_occ = segments_blocked(centre, kp, np.concatenate(others), tail=0.0) if others else np.zeros(12, bool)
        verts = world_meshes[i].vertices
        vuv, vdepth = camera.project(verts)
        if np.all(vdepth > 1e-6):
            box = np.array([vuv[:, 0].min() + 0.5, vuv[:, 1].min() + 0.5, vuv[:, 0].max() + 0.5, vuv[:, 1].max() + 0.5])
        else:
            box = np.full(4, np.nan)
        if size is None:
            in_image = in_front
        out.append(VehicleAnnotation(uv, depth, in_image, self_occ & in_front, other_occ & in_front, box))
    assert all(len(a.uv) == NUM_KEYPOINTS for a in out)
    return out
