"""The simulated camera: RGB, metric z-depth, normals and hit mask by Open3D ray casting.

The camera of a run is the ``camera`` section of ``configs/sim.yaml`` (:meth:`PinholeCamera.from_config`),
there with the paper's values (docs/design.md): 480 x 480 pixels, f = 300 px (77.32 degrees
field of view), depth beyond 3.5 m invalid. Pixel centres sit at integer coordinates (OpenCV),
so the principal point of a W x H image is ((W - 1) / 2, (H - 1) / 2).

Open3D's ``RaycastingScene`` is built once per scene (:mod:`.raycast`). Rays are cast
with unnormalised camera-frame directions ``((u - cx) / fx, (v - cy) / fy, 1)``, so the
returned hit distance *is* the z-depth, with no per-pixel division.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from ..errors import InputError, positive_number, whole_number
from ..geometry import intrinsics_matrix
from ..scenes import Scene
from .raycast import INVALID_ID, cast_rays


MAX_CAMERA_PX = 4096
"""The largest simulated image side, pixels (``camera.width``, ``camera.height``): a 4K frame; a
larger one only runs out of memory (its rays are 24 bytes a pixel)."""


MAX_FOV_DEG = 170.0
"""The widest field of view (degrees, across the larger image side) of a simulated pinhole camera: at 180
its focal length is 0 and every ray lies in the image plane (the renderer's z-depth is then 0 everywhere)."""


def background_color(value) -> np.ndarray:
    """(3,) uint8 RGB of ``camera.background``, where a ray hits nothing: three integers 0-255;
    InputError naming the key for anything else."""
    try:
        rgb = np.array([float(channel) for channel in value], np.float64)
    except (TypeError, ValueError):
        rgb = np.zeros(0)
    if rgb.shape != (3,) or not np.all((rgb >= 0) & (rgb <= 255) & (rgb == np.round(rgb))):
        raise InputError(f"camera.background must be an RGB colour of three integers 0-255, got {value!r}")
    return rgb.astype(np.uint8)


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics (pixels) and the depth sensor's range (metres)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    max_depth: float

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise InputError(f"camera size must be positive, got {self.width} x {self.height}")
        if not (self.fx > 0 and self.fy > 0):
            raise InputError(f"camera focal length must be positive, got fx={self.fx}, fy={self.fy}")
        if not self.max_depth > 0:
            raise InputError(f"camera max_depth must be positive, got {self.max_depth}")

    @classmethod
    def from_config(cls, conf) -> "PinholeCamera":
        """From the ``camera`` section of ``configs/sim.yaml`` (centred principal point); InputError
        naming the key for a size outside [1, :data:`MAX_CAMERA_PX`] pixels, a focal length or a
        range that is not a positive number, a field of view past :data:`MAX_FOV_DEG`, a
        ``background`` that is no colour (:func:`background_color`)."""
        width, height = (whole_number(conf[key], f"camera.{key}", 1, MAX_CAMERA_PX) for key in ("width", "height"))
        focal = positive_number(conf.focal_px, "camera.focal_px", "pixels")
        widest = max(width, height) / 2.0 / np.tan(np.radians(MAX_FOV_DEG / 2.0))  # the shortest focal length
        if focal < widest:
            raise InputError(f"camera.focal_px {focal:g} gives a {width} x {height} camera a field of view past "
                             f"{MAX_FOV_DEG:g} degrees; a pinhole camera of that size needs at least {widest:.1f} px")
        if "background" in conf:
            background_color(conf.background)
        return cls(width, height, focal, focal, (width - 1) / 2.0, (height - 1) / 2.0,
                   positive_number(conf.max_depth, "camera.max_depth", "metres"))

    @classmethod
    def from_K(cls, K: np.ndarray, width: int, height: int, max_depth: float) -> "PinholeCamera":
        K = np.asarray(K, np.float64)
        return cls(int(width), int(height), float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                   float(max_depth))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) float64 intrinsic matrix."""
        return intrinsics_matrix(self.fx, self.fy, self.cx, self.cy)

    @property
    def horizontal_fov_deg(self) -> float:
        return float(np.degrees(2 * np.arctan(self.width / 2.0 / self.fx)))

    def ray_directions(self) -> np.ndarray:
        """(H, W, 3) float32 camera-frame directions with unit z (so hit distance = z-depth)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        return np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], -1).astype(np.float32)


@dataclass
class Frame:
    """One rendered view (or a batch, with a leading B axis on every array).

    Attributes:
        rgb: (H, W, 3) uint8; background colour where nothing is hit.
        depth: (H, W) float32 metres, z-depth along the optical axis; NaN where no
            surface is hit or the hit is beyond ``max_depth`` (invalid, never 0).
        normals: (H, W, 3) float32 unit surface normals in the *world* frame, turned
            towards the camera; 0 where nothing is hit.
        hit_mask: (H, W) bool, the ray hit a surface at any distance (RGB is valid
            there even beyond the depth sensor's range).
        T_world_cam: (4, 4) float64 camera pose.
        K: (3, 3) float64 intrinsics.
        hit_depth: (H, W) float32 metres, z-depth of every hit at any distance (no
            sensor range); NaN only where no surface is hit. What a monocular depth
            model sees (the emulated depth source degrades it); None if not rendered.
    """

    rgb: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    hit_mask: np.ndarray
    T_world_cam: np.ndarray
    K: np.ndarray = field(repr=False)
    hit_depth: np.ndarray | None = field(default=None, repr=False)

    def __getitem__(self, index: int) -> "Frame":
        """The `index`-th frame of a batch."""
        return Frame(self.rgb[index], self.depth[index], self.normals[index], self.hit_mask[index],
                     self.T_world_cam[index], self.K, None if self.hit_depth is None else self.hit_depth[index])


class _Shader:
    """Per-triangle lookup tables for colouring ray hits in one compiled pass.

    Every material becomes a texture in one flat texel array: a textured material its
    image, an untextured one a single texel of its colour. Per triangle we store its
    UV origin and edge vectors, its texture's offset, width and height, and whether it
    takes interpolated vertex colours instead.
    """

    def __init__(self, scene: Scene) -> None:
        texels, offsets, sizes = [], [], []
        offset = 0
        for material in scene.materials:
            image = material.texture if material.texture is not None else material.color.reshape(1, 1, 3)
            texels.append(image.reshape(-1, 3))
            offsets.append(offset)
            sizes.append(image.shape[:2])
            offset += image.shape[0] * image.shape[1]
        self.texels = np.ascontiguousarray(np.concatenate(texels))
        mat = scene.triangle_material
        sizes = np.asarray(sizes, np.int64)
        # (T, 3) int64: texel offset, width, height
        self.tri_texture = np.ascontiguousarray(
            np.stack([np.asarray(offsets, np.int64)[mat], sizes[mat, 1], sizes[mat, 0]], 1))
        if scene.triangle_uvs is not None:
            uv = scene.triangle_uvs
            # (T, 6) float32: uv0, uv1 - uv0, uv2 - uv0
            self.tri_uv = np.ascontiguousarray(
                np.concatenate([uv[:, 0], uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]], 1), np.float32)
        else:
            self.tri_uv = np.zeros((len(mat), 6), np.float32)
        vertex_colored = np.array([m.use_vertex_colors for m in scene.materials], bool)
        self.tri_vertex_colored = np.ascontiguousarray(vertex_colored[mat])
        self.triangle_colors = (np.ascontiguousarray(scene.vertex_colors[scene.triangles], np.float32)
                                if vertex_colored.any() else np.zeros((1, 3, 3), np.float32))


@numba.njit(parallel=True, cache=True, fastmath=True)
def _shade_hits(t_hit, prim, bary, face_normals, rays, max_depth, tri_texture, tri_uv, texels,
                tri_vertex_colored, triangle_colors, background, depth, hit_depth, rgb, normals,
                hit):  # pragma: no cover
    """One pass over N rays (N, 6): depth with range limit (and without: `hit_depth`), texture/colour
    lookup, normals facing the camera."""
    invalid = np.uint32(INVALID_ID)
    for i in numba.prange(t_hit.shape[0]):
        p = prim[i]
        if p == invalid:
            hit[i] = False
            depth[i] = np.nan
            hit_depth[i] = np.nan
            for c in range(3):
                rgb[i, c] = background[c]
                normals[i, c] = 0.0
            continue
        hit[i] = True
        hit_depth[i] = t_hit[i]
        depth[i] = t_hit[i] if t_hit[i] <= max_depth else np.nan
        b1, b2 = bary[i, 0], bary[i, 1]
        if tri_vertex_colored[p]:
            for c in range(3):
                value = (triangle_colors[p, 0, c] * (1.0 - b1 - b2) + triangle_colors[p, 1, c] * b1
                         + triangle_colors[p, 2, c] * b2)
                rgb[i, c] = np.uint8(min(max(value, 0.0), 255.0))
        else:
            width, height = tri_texture[p, 1], tri_texture[p, 2]
            u = tri_uv[p, 0] + b1 * tri_uv[p, 2] + b2 * tri_uv[p, 4]
            v = tri_uv[p, 1] + b1 * tri_uv[p, 3] + b2 * tri_uv[p, 5]
            u -= np.floor(u)  # wrap mode repeat
            v -= np.floor(v)
            col = min(np.int64(u * width), width - 1)
            row = min(np.int64((1.0 - v) * height), height - 1)  # OpenGL UVs: v up
            texel = tri_texture[p, 0] + row * width + col
            for c in range(3):
                rgb[i, c] = texels[texel, c]
        dot = (face_normals[i, 0] * rays[i, 3] + face_normals[i, 1] * rays[i, 4]
               + face_normals[i, 2] * rays[i, 5])
        sign = -1.0 if dot > 0 else 1.0
        for c in range(3):
            normals[i, c] = sign * face_normals[i, c]


@numba.njit(parallel=True, cache=True)
def _make_rays(directions, T, rays):  # pragma: no cover
    """(N, 3) camera-frame directions, (B, 4, 4) poses -> fills (B, N, 6) world rays."""
    for b in range(T.shape[0]):
        for i in numba.prange(directions.shape[0]):
            for c in range(3):
                rays[b, i, c] = T[b, c, 3]
                rays[b, i, 3 + c] = (T[b, c, 0] * directions[i, 0] + T[b, c, 1] * directions[i, 1]
                                     + T[b, c, 2] * directions[i, 2])


class Renderer:
    """Renders a scene through a :class:`PinholeCamera` at any ``T_world_cam`` pose(s).

    Args:
        scene: the scene (world frame, Z-up, metres).
        camera: intrinsics and range (a run's: :meth:`PinholeCamera.from_config` of ``camera``).
        background: (3,) RGB 0-255 where a ray hits nothing (``camera.background``).
    """

    def __init__(self, scene: Scene, camera: PinholeCamera, background) -> None:
        self.scene = scene
        self.camera = camera
        self.background = background_color(background)
        self._directions = self.camera.ray_directions()  # (H, W, 3) camera frame
        self._shader = _Shader(scene)

    def rays(self, T_world_cams: np.ndarray) -> np.ndarray:
        """(B, 4, 4) poses -> (B, H, W, 6) float32 world-frame rays (origin, direction)."""
        T = np.asarray(T_world_cams, np.float64).reshape(-1, 4, 4)
        if not np.isfinite(T).all():
            raise InputError("camera pose contains NaN or infinite values")
        B, (H, W) = len(T), self._directions.shape[:2]
        rays = np.empty((B, H * W, 6), np.float32)
        _make_rays(self._directions.reshape(-1, 3), T.astype(np.float32), rays)
        rays = rays.reshape(B, H, W, 6)
        return rays

    def render(self, T_world_cam: np.ndarray) -> Frame:
        """Render one (4, 4) pose; see :class:`Frame` for the outputs."""
        return self.render_batch(np.asarray(T_world_cam)[None])[0]

    def render_batch(self, T_world_cams: np.ndarray, frames_per_cast: int = 1) -> Frame:
        """Render (B, 4, 4) poses; arrays of the returned :class:`Frame` carry a leading B axis.

        Rays are cast `frames_per_cast` frames at a time: Open3D gains nothing from
        larger casts (it is memory-bound), and one frame's rays and hits stay in cache
        for the shading pass that follows.
        """
        T = np.asarray(T_world_cams, np.float64).reshape(-1, 4, 4)
        B, H, W = len(T), self.camera.height, self.camera.width
        n = H * W
        depth = np.empty((B, n), np.float32)
        hit_depth = np.empty((B, n), np.float32)
        rgb = np.empty((B, n, 3), np.uint8)
        normals = np.empty((B, n, 3), np.float32)
        hit = np.empty((B, n), bool)
        shader = self._shader
        step = max(int(frames_per_cast), 1)
        for start in range(0, B, step):
            chunk = slice(start, min(start + step, B))
            rays = self.rays(T[chunk]).reshape(-1, 6)
            answer = cast_rays(self.scene, rays)
            m = len(rays)
            _shade_hits(answer["t_hit"].reshape(m), answer["primitive_ids"].reshape(m),
                        answer["primitive_uvs"].reshape(m, 2), answer["primitive_normals"].reshape(m, 3),
                        rays, np.float32(self.camera.max_depth), shader.tri_texture,
                        shader.tri_uv, shader.texels, shader.tri_vertex_colored, shader.triangle_colors,
                        self.background, depth[chunk].reshape(m), hit_depth[chunk].reshape(m),
                        rgb[chunk].reshape(m, 3), normals[chunk].reshape(m, 3), hit[chunk].reshape(m))
        return Frame(rgb=rgb.reshape(B, H, W, 3), depth=depth.reshape(B, H, W),
                     normals=normals.reshape(B, H, W, 3), hit_mask=hit.reshape(B, H, W), T_world_cam=T,
                     K=self.camera.K, hit_depth=hit_depth.reshape(B, H, W))
