"""Rendering and writing every frame of one camera view (one job per view, picklable).

This module does not import torch, so worker processes that render views start quickly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.formats import dexycb
from worker.formats.files import encode_image, npz_bytes
from worker.synth.render import (
    DEFAULT_LIGHTING,
    Lighting,
    ModelMesh,
    SceneMesh,
    TextureAtlas,
    combine,
    prepare_view,
    render_view,
)
from worker.synth.scene import CameraSpec, smooth_normals


@dataclass(frozen=True)
class ViewJob:
    """Everything needed to render and write one camera's frames.

    Attributes:
        seed: capture seed (frame noise is drawn from ``default_rng([seed, view, frame])``).
        view: camera index. directory: the ``<sequence>/<serial>`` folder to fill.
        camera: the camera, table frame. width, height: image size, pixels.
        table: the table mesh (table frame). objects: K object meshes (model frames).
        object_poses: (F, K, 3, 4) model-to-table poses.
        hand_vertices: (F, V, 3) table frame, metres; hand_faces: (Fh, 3); hand_color: BGR.
        labels: per-frame label arrays in this camera's frame, keyed by label name, leading F.
        textures: texture images indexed by the meshes' ``texture`` fields.
        arm: extra meshes drawn with the hand and labelled background (worker.synth.forearm):
            (vertices (F, V, 3) table frame, faces, BGR colour) each; none by default.
        lighting: how the scene is lit (worker.synth.render.Lighting).
    """

    seed: int
    view: int
    directory: Path
    camera: CameraSpec
    width: int
    height: int
    table: ModelMesh
    objects: list[ModelMesh]
    object_poses: np.ndarray
    hand_vertices: np.ndarray
    hand_faces: np.ndarray
    hand_color: tuple[float, float, float]
    labels: dict[str, np.ndarray]
    textures: list[np.ndarray]
    arm: tuple[tuple[np.ndarray, np.ndarray, tuple[float, float, float]], ...] = ()
    lighting: Lighting = DEFAULT_LIGHTING


def _hand_mesh(job: ViewJob, frame: int, label: int) -> SceneMesh:
    verts = job.hand_vertices[frame]
    return SceneMesh(verts, job.hand_faces, smooth_normals(verts, job.hand_faces), None, -1,
                     job.hand_color, label)


def run_view_job(job: ViewJob, hand_label: int) -> list[str]:
    """Render and write colour, depth and labels of every frame; returns the written names."""
    cam = job.camera
    view = prepare_view(cam.K, cam.dist, cam.T_cam_to_table, job.width, job.height)
    atlas = TextureAtlas.build(job.textures)
    identity = np.eye(3, 4)
    written = []
    for frame in range(job.object_poses.shape[0]):
        meshes = [job.table.posed(identity)]
        meshes += [m.posed(job.object_poses[frame, k]) for k, m in enumerate(job.objects)]
        meshes.append(_hand_mesh(job, frame, hand_label))
        meshes += [SceneMesh(v[frame], faces, smooth_normals(v[frame], faces), None, -1, color,
                             dexycb.BACKGROUND_SEG_VALUE) for v, faces, color in job.arm]
        rng = np.random.default_rng([job.seed, job.view, frame])
        color, depth, seg = render_view(combine(meshes), view, atlas, rng, job.lighting)
        labels = {name: values[frame] for name, values in job.labels.items()}
        labels[dexycb.SEG] = seg
        files = {
            dexycb.color_file(frame): encode_image(".jpg", color),
            dexycb.depth_file(frame): encode_image(".png", depth),
            dexycb.labels_file(frame): npz_bytes(labels),
        }
        for name, data in files.items():
            (job.directory / name).write_bytes(data)
            written.append(name)
    return written
