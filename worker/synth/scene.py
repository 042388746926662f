"""The static scene of a synthetic capture: camera rig, table and object placement.

Everything here is in the *table frame*: origin at the centre of the workspace on the table top,
z up, the subject sitting on the -y side; metres. (The written capture re-expresses it all in the
master camera's frame; see worker.synth.capture.)
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import sparse

from worker.geometry.cameras import intrinsics_matrix, look_at
from worker.geometry.mesh_io import Mesh
from worker.geometry.transforms import axis_angle_to_matrix, make_pose
from worker.synth.render import ModelMesh
from worker.synth.shapes import CATALOGUE, ObjectSpec, object_mesh, object_texture

WORKSPACE_CENTRE = np.array([0.0, 0.02, 0.08])  # where the cameras aim, metres
TABLE_SIZE = (1.4, 1.0)  # x, y extent of the table top, metres
TABLE_CENTRE_Y = 0.1
TABLE_TILE = 0.1  # the table is tiled so that no triangle reaches behind a camera
TABLE_COLOR = (120, 160, 200)  # light wood, BGR


@dataclass(frozen=True)
class CameraSpec:
    """One calibrated colour camera (depth is aligned to it).

    Attributes:
        serial: 12-digit serial number.
        K: (3, 3) intrinsics, pixels; dist: (5,) OpenCV (k1, k2, p1, p2, k3).
        T_cam_to_table: (3, 4) camera-to-table pose, metres (OpenCV camera axes).
    """

    serial: str
    K: np.ndarray
    dist: np.ndarray
    T_cam_to_table: np.ndarray


@dataclass(frozen=True)
class PlacedObject:
    """An object resting on the table: catalogue spec and model-to-table pose (3, 4)."""

    spec: ObjectSpec
    T_obj_to_table: np.ndarray


def make_serials(seed: int, views: int) -> list[str]:
    """Deterministic distinct 12-digit serials for the cameras of capture ``seed``."""
    return [f"8{seed % 100000:05d}{60125 + 371 * i:06d}" for i in range(views)]


def make_cameras(rng: np.random.Generator, serials: list[str], width: int, height: int
                 ) -> list[CameraSpec]:
    """A ring of cameras 0.6-0.9 m from the workspace at 30-50 degrees elevation.

    Focal lengths near a D415 colour camera's 615 px at 640 x 480 (scaled with the width);
    every other camera gets a small radial-tangential distortion.
    """
    scale = width / 640.0
    cams = []
    for i, serial in enumerate(serials):
        azimuth = 2.0 * np.pi * i / len(serials) + rng.uniform(-0.15, 0.15) - np.pi / 2.0
        elevation = np.deg2rad(rng.uniform(30.0, 50.0))
        distance = rng.uniform(0.6, 0.9)
        target = WORKSPACE_CENTRE + rng.normal(0.0, 0.025, 3) * [1.0, 1.0, 0.5]
        direction = np.array([np.cos(elevation) * np.cos(azimuth),
                              np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
        pose = look_at(target + distance * direction, target, np.array([0.0, 0.0, 1.0]))
        roll = axis_angle_to_matrix(np.array([0.0, 0.0, rng.normal(0.0, np.deg2rad(2.0))]))
        pose = make_pose(pose[:, :3] @ roll, pose[:, 3])
        fx = (615.0 + rng.normal(0.0, 4.0)) * scale
        K = intrinsics_matrix(fx, fx + rng.normal(0.0, 0.8) * scale,
                              (width - 1) / 2.0 + rng.normal(0.0, 3.0) * scale,
                              (height - 1) / 2.0 + rng.normal(0.0, 3.0) * scale)
        dist = np.zeros(5)
        if i % 2 == 1:
            dist = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.04, 0.04),
                             rng.normal(0.0, 6e-4), rng.normal(0.0, 6e-4), 0.0])
        cams.append(CameraSpec(serial, K, dist, pose))
    return cams


def _footprint(spec: ObjectSpec) -> float:
    """Radius (metres) of a circle around the object's footprint on the table."""
    return float(np.linalg.norm(spec.half_extents[:2]))


def _yaw_pose(spec: ObjectSpec, xy: np.ndarray, yaw: float) -> np.ndarray:
    rot = axis_angle_to_matrix(np.array([0.0, 0.0, yaw]))
    return make_pose(rot, np.array([xy[0], xy[1], spec.half_extents[2]]))


def place_objects(rng: np.random.Generator, ycb_ids: list[int], grasp_ind: int,
                  target_yaw: float) -> list[PlacedObject]:
    """Put the target near the front centre and the others behind / left of it, non-overlapping.

    The region right of and in front of the target stays free for the approaching right hand.
    """
    target = CATALOGUE[ycb_ids[grasp_ind]]
    t_xy = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.06, 0.0)])
    placed: dict[int, PlacedObject] = {grasp_ind: PlacedObject(target, _yaw_pose(target, t_xy,
                                                                                 target_yaw))}
    centres = [(t_xy, _footprint(target) + 0.12)]  # generous gap around the grasped object
    for k, ycb_id in enumerate(ycb_ids):
        if k == grasp_ind:
            continue
        spec = CATALOGUE[ycb_id]
        r = _footprint(spec)
        # Fallback after many misses: a slot in the back rows, beyond the sampled region.
        slot = len(placed)
        xy = np.array([-0.45 + 0.18 * (slot % 6), 0.36 + 0.14 * (slot // 6)])
        for _ in range(400):
            cand = np.array([rng.uniform(-0.3, 0.22), rng.uniform(-0.05, 0.3)])
            in_hand_path = cand[0] > t_xy[0] - 0.02 and cand[1] < t_xy[1] + 0.2
            if not in_hand_path and all(
                np.linalg.norm(cand - c) > r + extra for c, extra in centres
            ):
                xy = cand
                break
        placed[k] = PlacedObject(spec, _yaw_pose(spec, xy, rng.uniform(-np.pi, np.pi)))
        centres.append((xy, r + 0.02))
    return [placed[k] for k in range(len(ycb_ids))]


def table_mesh() -> Mesh:
    """Tiled table-top rectangle at z = 0 (metres), UVs spanning the table texture once."""
    nx, ny = (round(s / TABLE_TILE) for s in TABLE_SIZE)
    xs = np.linspace(-TABLE_SIZE[0] / 2, TABLE_SIZE[0] / 2, nx + 1)
    ys = np.linspace(-TABLE_SIZE[1] / 2, TABLE_SIZE[1] / 2, ny + 1) + TABLE_CENTRE_Y
    gx, gy = np.meshgrid(xs, ys)
    vertices = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    uvs = np.column_stack([np.repeat([np.linspace(0, 1, nx + 1)], ny + 1, 0).ravel(),
                           np.repeat(np.linspace(0, 1, ny + 1), nx + 1)])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    a = (j * (nx + 1) + i).ravel()
    b, c, d = a + 1, a + nx + 2, a + nx + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return Mesh(vertices, faces, uvs, faces.copy())


def table_texture(rng: np.random.Generator, size: int = 1024) -> np.ndarray:
    """(size, size, 3) uint8 BGR wood-like table texture with a faint cutting-mat grid."""
    rows = np.arange(size, dtype=np.float64)[:, None]
    cols = np.arange(size, dtype=np.float64)[None, :]
    phase = rng.uniform(0, 2 * np.pi, 3)
    grain = (np.sin(rows / 5.0 + 3.0 * np.sin(cols / 90.0 + phase[0])) * 0.5
             + np.sin(rows / 1.7 + phase[1]) * 0.2 + np.sin(cols / 230.0 + phase[2]) * 0.3)
    img = np.asarray(TABLE_COLOR, np.float64) * (1.0 + 0.08 * grain[..., None])
    img = np.clip(img, 0, 255).astype(np.uint8)
    step = size // 14
    for k in range(0, size, step):
        cv2.line(img, (k, 0), (k, size - 1), (95, 130, 165), 1)
        cv2.line(img, (0, k), (size - 1, k), (95, 130, 165), 1)
    return img


def crease_normals(vertices: np.ndarray, faces: np.ndarray, max_angle_deg: float = 40.0
                   ) -> np.ndarray:
    """Per-corner unit normals (F, 3, 3): smooth across edges flatter than ``max_angle_deg``.

    Each corner averages the area-weighted normals of the faces around its vertex that are
    within the angle of its own face, so box edges stay sharp and cylinder sides stay round.
    """
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    unit = fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    corner_face = np.repeat(np.arange(len(faces)), 3)
    corner_vertex = faces.reshape(-1)
    order = np.argsort(corner_vertex, kind="stable")
    out = np.zeros((len(faces) * 3, 3))
    cos_max = np.cos(np.deg2rad(max_angle_deg))
    # Pair every corner with every face sharing its vertex (small meshes: a dense pairing is fine).
    bounds = np.searchsorted(corner_vertex[order], np.arange(len(vertices) + 1))
    for v in np.flatnonzero(np.diff(bounds)):
        corners = order[bounds[v]:bounds[v + 1]]
        f = corner_face[corners]
        similar = unit[f] @ unit[f].T >= cos_max
        out[corners] = similar.astype(np.float64) @ fn[f]
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
    return out.reshape(len(faces), 3, 3)


def smooth_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-corner unit vertex normals (..., F, 3, 3) of meshes (..., V, 3), area weighted."""
    batch, n_v = vertices.shape[:-2], vertices.shape[-2]
    v = vertices.reshape(-1, n_v, 3)
    tri = v[:, faces]  # (B, F, 3, 3)
    fn = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])  # (B, F, 3)
    n_f = len(faces)
    incidence = sparse.csr_matrix(
        (np.ones(3 * n_f), (faces.T.reshape(-1), np.tile(np.arange(n_f), 3))), shape=(n_v, n_f)
    )
    vn = (incidence @ fn.transpose(1, 0, 2).reshape(n_f, -1)).reshape(n_v, -1, 3)
    vn = vn.transpose(1, 0, 2)
    vn /= np.maximum(np.linalg.norm(vn, axis=-1, keepdims=True), 1e-300)
    return vn[:, faces].reshape(batch + (n_f, 3, 3))


def object_sdf(spec: ObjectSpec, points_obj: np.ndarray) -> np.ndarray:
    """Signed distance (..., ) metres of model-frame points (..., 3) to the object (inside < 0)."""
    half = spec.half_extents
    if spec.kind == "cylinder":
        radial = np.linalg.norm(points_obj[..., :2], axis=-1) - half[0]
        axial = np.abs(points_obj[..., 2]) - half[2]
        q = np.stack([radial, axial], axis=-1)
    else:
        q = np.abs(points_obj) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    return outside + np.minimum(q.max(axis=-1), 0.0)


def _corner_uvs(mesh: Mesh) -> np.ndarray:
    """(F, 3, 2) texture coordinates of every face corner of a textured mesh."""
    if mesh.uvs is None or mesh.face_uvs is None:
        raise ValueError("the mesh has no texture coordinates")
    return mesh.uvs[mesh.face_uvs]


def build_meshes(
    rng: np.random.Generator, specs: list[ObjectSpec]
) -> tuple[ModelMesh, list[ModelMesh], list[np.ndarray], tuple[float, float, float]]:
    """Renderable meshes: the table (table frame), the objects (model frames), their textures
    (texture 0 is the table's, k + 1 object k's) and a skin colour (BGR) for the hand."""
    table = table_mesh()
    up = np.broadcast_to([0.0, 0.0, 1.0], (len(table.faces), 3, 3)).copy()
    textures = [table_texture(rng)]
    table_mm = ModelMesh(table.vertices, table.faces, up, _corner_uvs(table), 0,
                         (0.0, 0.0, 0.0), 0)
    objects = []
    for spec in specs:
        mesh = object_mesh(spec)
        textures.append(object_texture(spec))
        objects.append(ModelMesh(mesh.vertices, mesh.faces, crease_normals(mesh.vertices,
                                 mesh.faces), _corner_uvs(mesh), len(textures) - 1,
                                 (0.0, 0.0, 0.0), spec.ycb_id))
    tone = rng.uniform(-1.0, 1.0)
    skin = (float(120 + 25 * tone), float(150 + 25 * tone), float(205 + 20 * tone))
    return table_mm, objects, textures, skin
