"""Deferred shading of a triangle scene into colour, depth and segmentation for one camera.

Geometry is given in the *scene frame* (the synthesiser's table frame, metres). Each view is
rasterised with an ideal pinhole (worker.geometry.raster); a lens with distortion is handled by
rendering a slightly larger undistorted image and resampling it at the undistorted position of
every output pixel, so pixel (u, v) of the result shows what OpenCV's model projects to (u, v).
Depth is the camera z of the nearest surface; seg and depth always come from the same sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from worker.geometry.cameras import pixels_to_rays
from worker.geometry.raster import Fragments, rasterize
from worker.synth.sensor import finish_color, simulate_depth

AMBIENT = 0.38
DIFFUSE = 0.72
LIGHT_DIR_SCENE = np.array([0.35, -0.45, 1.0]) / np.linalg.norm([0.35, -0.45, 1.0])
_BACKGROUND_TOP = np.array([92.0, 88.0, 84.0])  # BGR wall colour at the image top
_BACKGROUND_BOTTOM = np.array([58.0, 60.0, 62.0])


@dataclass(frozen=True)
class Lighting:
    """Ambient light plus one distant light, in the scene frame.

    Attributes:
        ambient, diffuse: shading = ambient + diffuse * max(0, normal . direction).
        direction: (3,) unit vector towards the light, scene frame.
    """

    ambient: float = AMBIENT
    diffuse: float = DIFFUSE
    direction: tuple[float, float, float] = (float(LIGHT_DIR_SCENE[0]),
                                             float(LIGHT_DIR_SCENE[1]),
                                             float(LIGHT_DIR_SCENE[2]))


DEFAULT_LIGHTING = Lighting()


def varied_lighting(rng: np.random.Generator) -> Lighting:
    """A room's light drawn at random (``dexlabel synth --varied-light``): indoor footage is
    lit as much by light bounced off walls and ceiling as by its lamps, so the ambient share
    is drawn higher than the default's (which leaves the side of a hand away from the light
    dark), and the lamp anywhere above the table."""
    ambient = rng.uniform(0.45, 0.65)
    diffuse = rng.uniform(0.4, 0.65)
    elevation = np.deg2rad(rng.uniform(35.0, 80.0))
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    direction = (np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                 np.sin(elevation))
    return Lighting(float(ambient), float(diffuse),
                    (float(direction[0]), float(direction[1]), float(direction[2])))


@dataclass(frozen=True)
class SceneMesh:
    """One mesh instance at one frame, in the scene frame.

    Attributes:
        vertices: (N, 3) metres.
        faces: (F, 3) int64.
        corner_normals: (F, 3, 3) unit normals per face corner.
        corner_uvs: (F, 3, 2) texture coordinates per corner, or None for a plain colour.
        texture: index into the texture list, or -1.
        color: (3,) BGR albedo in [0, 255], used when ``texture`` is -1.
        label: segmentation value written where this mesh is the nearest surface.
    """

    vertices: np.ndarray
    faces: np.ndarray
    corner_normals: np.ndarray
    corner_uvs: np.ndarray | None
    texture: int
    color: tuple[float, float, float]
    label: int


@dataclass(frozen=True)
class ModelMesh:
    """A mesh in its own frame, ready to be posed (fields as :class:`SceneMesh`)."""

    vertices: np.ndarray  # (N, 3) metres, model frame
    faces: np.ndarray  # (F, 3)
    corner_normals: np.ndarray  # (F, 3, 3) model frame
    corner_uvs: np.ndarray | None  # (F, 3, 2)
    texture: int
    color: tuple[float, float, float]
    label: int

    def posed(self, pose: np.ndarray) -> SceneMesh:
        """The mesh moved by a (3, 4) model-to-scene pose."""
        rot, trans = pose[:, :3], pose[:, 3]
        return SceneMesh(self.vertices @ rot.T + trans, self.faces, self.corner_normals @ rot.T,
                         self.corner_uvs, self.texture, self.color, self.label)


@dataclass(frozen=True)
class SceneFrame:
    """All meshes of one frame concatenated (F triangles in total), scene frame."""

    vertices: np.ndarray  # (N, 3) metres
    faces: np.ndarray  # (F, 3) int64
    corner_normals: np.ndarray  # (F, 3, 3) float32
    corner_uvs: np.ndarray  # (F, 3, 2) float32, zeros where untextured
    texture: np.ndarray  # (F,) int64, -1 for plain colour
    color: np.ndarray  # (F, 3) float32 BGR
    label: np.ndarray  # (F,) uint8


def combine(meshes: list[SceneMesh]) -> SceneFrame:
    """Concatenate mesh instances into one :class:`SceneFrame`."""
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    per_face = [len(m.faces) for m in meshes]
    return SceneFrame(
        vertices=np.concatenate([m.vertices for m in meshes]),
        faces=np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=False)]),
        corner_normals=np.concatenate([m.corner_normals for m in meshes]).astype(np.float32),
        corner_uvs=np.concatenate([
            m.corner_uvs if m.corner_uvs is not None else np.zeros((len(m.faces), 3, 2))
            for m in meshes
        ]).astype(np.float32),
        texture=np.repeat([m.texture for m in meshes], per_face).astype(np.int64),
        color=np.repeat(np.array([m.color for m in meshes], np.float32), per_face, axis=0),
        label=np.repeat([m.label for m in meshes], per_face).astype(np.uint8),
    )


@dataclass(frozen=True)
class ViewCamera:
    """A camera prepared for rendering.

    Attributes:
        K: (3, 3) intrinsics of the output image, pixels; dist: (5,) OpenCV coefficients.
        T_cam_to_scene: (3, 4) camera-to-scene pose, metres.
        width, height: output size, pixels.
        render_K, render_size: pinhole used for rasterising (padded when the lens distorts).
        map_xy: (H, W, 2) float32 render-image position of each output pixel, or None.
        sample: (H * W,) int64 nearest render-image pixel of each output pixel, or None.
        rays: (H' * W', 3) float32 viewing ray of each render-image pixel, scene frame.
        background: (H', 3) float32 BGR colour of each render-image row where nothing is drawn.
    """

    K: np.ndarray
    dist: np.ndarray
    T_cam_to_scene: np.ndarray
    width: int
    height: int
    render_K: np.ndarray
    render_size: tuple[int, int]
    map_xy: np.ndarray | None
    sample: np.ndarray | None
    rays: np.ndarray
    background: np.ndarray


def _scene_rays(render_K: np.ndarray, rot: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H' * W', 3) float32 rays through every render-image pixel, rotated into the scene."""
    ys, xs = np.mgrid[0:size[1], 0:size[0]].astype(np.float64)
    pix = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)], axis=1)
    return (pix @ np.linalg.inv(render_K).T @ rot.T).astype(np.float32)


def _finish_view(K: np.ndarray, dist: np.ndarray, T: np.ndarray, width: int, height: int,
                 render_K: np.ndarray, size: tuple[int, int], map_xy: np.ndarray | None,
                 sample: np.ndarray | None) -> ViewCamera:
    background = np.linspace(_BACKGROUND_TOP, _BACKGROUND_BOTTOM, size[1]).astype(np.float32)
    return ViewCamera(K, dist, T, width, height, render_K, size, map_xy, sample,
                      _scene_rays(render_K, T[:, :3], size), background)


def prepare_view(K: npt.ArrayLike, dist: npt.ArrayLike, T_cam_to_scene: npt.ArrayLike,
                 width: int, height: int) -> ViewCamera:
    """Precompute the padded pinhole, resampling maps and viewing rays of one camera."""
    K, dist = np.asarray(K, np.float64), np.asarray(dist, np.float64)
    T = np.asarray(T_cam_to_scene, np.float64)
    if not np.any(dist):
        return _finish_view(K, dist, T, width, height, K, (width, height), None, None)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    rays = pixels_to_rays(np.stack([xs, ys], axis=-1), K, dist)
    ideal = rays[..., :2] @ K[:2, :2].T + K[:2, 2]
    pad_x = int(np.ceil(max(0.0, -ideal[..., 0].min(), ideal[..., 0].max() - (width - 1)))) + 2
    pad_y = int(np.ceil(max(0.0, -ideal[..., 1].min(), ideal[..., 1].max() - (height - 1)))) + 2
    render_K = K.copy()
    render_K[0, 2] += pad_x
    render_K[1, 2] += pad_y
    map_xy = (ideal + [pad_x, pad_y]).astype(np.float32)
    rw = width + 2 * pad_x
    near = np.rint(ideal + [pad_x, pad_y]).astype(np.int64)
    sample = (near[..., 1] * rw + near[..., 0]).reshape(-1)
    return _finish_view(K, dist, T, width, height, render_K, (rw, height + 2 * pad_y), map_xy,
                        sample)


@dataclass(frozen=True)
class TextureAtlas:
    """Textures stacked top to bottom in one image, so one gather samples all of them.

    Attributes:
        image: (sum of heights, max width, 3) uint8 BGR.
        offset, height, width: (T,) int64 first row and size of each texture, pixels.
    """

    image: np.ndarray
    offset: np.ndarray
    height: np.ndarray
    width: np.ndarray

    @classmethod
    def build(cls, textures: list[np.ndarray]) -> TextureAtlas:
        """Stack (H_t, W_t, 3) uint8 textures."""
        heights = np.array([t.shape[0] for t in textures], np.int64)
        widths = np.array([t.shape[1] for t in textures], np.int64)
        image = np.zeros((int(heights.sum()), int(widths.max()), 3), np.uint8)
        offset = np.concatenate([[0], np.cumsum(heights)[:-1]]).astype(np.int64)
        for tex, row in zip(textures, offset, strict=True):
            image[row:row + tex.shape[0], :tex.shape[1]] = tex
        return cls(image, offset, heights, widths)


def _weighted(bary: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Interpolate per-corner values (P, 3, C) with weights (P, 3) -> (P, C)."""
    return (bary[:, 0, None] * corners[:, 0] + bary[:, 1, None] * corners[:, 1]
            + bary[:, 2, None] * corners[:, 2])


def _albedo(frame: SceneFrame, tri: np.ndarray, bary: np.ndarray, atlas: TextureAtlas
            ) -> np.ndarray:
    """Albedo (P, 3) float32 BGR of drawn pixels: nearest texel, or the mesh's plain colour."""
    albedo = frame.color[tri]
    tex = frame.texture[tri]
    has = np.flatnonzero(tex >= 0)
    t = tex[has]
    uv = _weighted(bary[has], frame.corner_uvs[tri[has]])
    h, w = atlas.height[t], atlas.width[t]
    col = np.clip(np.rint(uv[:, 0] * (w - 1)).astype(np.int64), 0, w - 1)
    row = np.clip(np.rint((1.0 - uv[:, 1]) * (h - 1)).astype(np.int64), 0, h - 1)
    albedo[has] = atlas.image[atlas.offset[t] + row, col]
    return albedo


def _shade(frame: SceneFrame, view: ViewCamera, frags: Fragments, atlas: TextureAtlas,
           lighting: Lighting) -> np.ndarray:
    """Lambertian + ambient colour (H', W', 3) float32 of the padded render image."""
    rw, rh = view.render_size
    img = np.repeat(view.background, rw, axis=0)  # (rh * rw, 3), row-major pixels
    tri, bary = frags.tri.reshape(-1)[frags.pixels], frags.bary
    normals = _weighted(bary, frame.corner_normals[tri])  # scene frame
    normals /= np.maximum(np.sqrt(np.einsum("pc,pc->p", normals, normals)), 1e-12)[:, None]
    # Smoothed normals can turn away from the camera near creases and silhouettes; there the
    # triangle's own normal, turned towards the camera, is used instead.
    rays = view.rays[frags.pixels]
    away = np.flatnonzero(np.einsum("pc,pc->p", normals, rays) > 0)
    corners = frame.vertices[frame.faces[tri[away]]]
    flat = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    flat /= np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-300)
    flat *= -np.sign(np.einsum("pc,pc->p", flat, rays[away]))[:, None]
    normals[away] = flat
    light = np.asarray(lighting.direction, np.float64).astype(np.float32)
    lit = lighting.ambient + lighting.diffuse * np.clip(normals @ light, 0.0, None)
    img[frags.pixels] = _albedo(frame, tri, bary, atlas) * lit[:, None]
    return img.reshape(rh, rw, 3)


def render_view(frame: SceneFrame, view: ViewCamera, atlas: TextureAtlas,
                rng: np.random.Generator, lighting: Lighting = DEFAULT_LIGHTING
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render one view of a frame (lit by ``lighting``).

    Returns:
        color (H, W, 3) uint8 BGR, depth (H, W) uint16 millimetres along camera z (0 = none),
        seg (H, W) uint8 with each mesh's label (0 where nothing is drawn).
    """
    rot, trans = view.T_cam_to_scene[:, :3], view.T_cam_to_scene[:, 3]
    points_cam = (frame.vertices - trans) @ rot
    rw, rh = view.render_size
    frags = rasterize(points_cam, frame.faces, view.render_K, rw, rh)
    shaded = _shade(frame, view, frags, atlas, lighting)
    seg_full = np.where(frags.tri >= 0, frame.label[np.maximum(frags.tri, 0)], 0).astype(np.uint8)
    depth_full = frags.depth
    if view.map_xy is not None and view.sample is not None:
        shaded = cv2.remap(shaded, view.map_xy[..., 0], view.map_xy[..., 1],
                           cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        shape = (view.height, view.width)
        seg_full = seg_full.reshape(-1)[view.sample].reshape(shape)
        depth_full = depth_full.reshape(-1)[view.sample].reshape(shape)
    color = finish_color(shaded, rng)
    depth = simulate_depth(depth_full, float(view.K[0, 0]), rng)
    return color, depth, seg_full
