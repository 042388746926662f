"""The image-based formats fed from a sequence's content: COCO (one document over every
view-frame image) and BOP (one scene per sequence and view). Flags travel beside the values:
see backend.exports.trust and the README's Export section."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from backend.exports import trust
from backend.exports.archive import ExportArchive
from backend.exports.content import SequenceContent, ViewContent
from backend.exports.writers import Exporter, Step, _Frames, _seq_dir, _world_meshes, seg_of
from worker.formats import bop, coco, dexycb, dexycb_frames, jsonfmt
from worker.geometry.cameras import distort_normalized
from worker.geometry.transforms import invert_pose, transform_points


class CocoExporter(Exporter):
    """One COCO keypoints document (``annotations.json``) over every view-frame image; hand
    keypoints from the accepted 2D labels (``options.labels = "2d"``, the default) or the solve
    projected (``"3d"``); object masks from the solve where there is one."""

    def __init__(self, archive: ExportArchive, options: dict[str, Any], include: str) -> None:
        super().__init__(archive, options, include)
        self.projected = options.get("labels") == "3d"
        self._member = archive.open("annotations.json")
        self._out = self._member.__enter__()
        self.writer = coco.CocoWriter(
            self._out, label_source="projected_3d" if self.projected else "annotated_2d",
            info={"include": include})

    def add(self, content: SequenceContent, step: Step) -> None:
        hand_key = f"hand:{content.hands[0].index}" if content.hands else None
        for v, view in enumerate(content.views):
            merged = content.merged_labels(v, hand_key) if hand_key else None
            for f in range(content.num_frames):
                seg = self._seg(content, view, f)
                self.writer.add_image(
                    f"{_seq_dir(content)}/{view.serial}/{dexycb.color_file(f)}",
                    view.camera.width, view.camera.height, seg=seg,
                    hand=self._hand(content, view, merged, f),
                    extra={"sequence_id": content.sequence_id, "serial": view.serial,
                           "frame": f},
                    objects=self._objects(content, f) if content.solve is not None else None)
                self.frames_written += 1
            step()

    def _seg(self, content: SequenceContent, view: ViewContent, frame: int) -> np.ndarray | None:
        if content.solve is None:
            return None
        # The frames of this format are the stored (raw) ones: the meshes are drawn where the
        # lens shows them, each vertex moved by the distortion.
        cam = view.camera
        w2c = invert_pose(cam.T_cam_to_world)
        meshes = []
        for verts, faces, value in _world_meshes(self, content, frame):
            points = transform_points(w2c, verts)
            z = points[:, 2:3]
            with np.errstate(divide="ignore", invalid="ignore"):
                xy = distort_normalized(points[:, :2] / z, cam.dist)
            meshes.append((np.concatenate([xy * z, z], axis=1), faces, value))
        return dexycb_frames.render_seg(meshes, cam.K, cam.width, cam.height)

    def _objects(self, content: SequenceContent, frame: int) -> dict[int, dict[str, Any]]:
        """Per seg value the object's trust and provenance; a flagged pose's instance is a crowd
        region (iscrowd 1): COCOeval neither rewards nor penalises detections of it."""
        out = {}
        for obj in content.objects:
            fields = trust.object_fields(content, obj.index, frame)
            out[obj.ycb_id] = {**fields, "iscrowd": 0 if fields["pose_valid"] else 1}
        return out

    def _hand(self, content: SequenceContent, view: ViewContent,
              merged: tuple[np.ndarray, np.ndarray] | None, frame: int
              ) -> coco.HandKeypoints | None:
        side = content.hands[0].side if content.hands else None
        if side not in ("right", "left"):
            return None
        extra = trust.hand_fields(content, frame)
        if self.projected:
            if content.solve is None:
                return None
            joints = content.solve.arrays["hand_joints"][frame]
            if not np.isfinite(joints).all():
                return None
            # Keypoints of a flagged solve are kept but not scored (a crowd region).
            extra["iscrowd"] = 0 if extra.get("hand_valid", True) else 1
            return coco.HandKeypoints(view.camera.project(joints), np.ones(21, bool),
                                      side=side, extra=extra)  # type: ignore[arg-type]
        if merged is None:
            return None
        xy = np.array(merged[0][frame], dtype=np.float64)
        # The page stores a joint that left the image at the border; where the solve puts it
        # outside, it is unlabelled (v = 0), not a border point.
        xy[trust.outside_joints(content, view, frame)] = np.nan
        return coco.HandKeypoints(xy, merged[1][frame], side=side,  # type: ignore[arg-type]
                                  extra=extra)

    def finish(self) -> None:
        self.writer.close()
        self._member.__exit__(None, None, None)


class BopExporter(Exporter):
    """BOP: one scene per sequence and view (ids in export order, listed in ``scenes.json``),
    pinhole images, and the models of every object seen."""

    def __init__(self, archive: ExportArchive, options: dict[str, Any], include: str) -> None:
        super().__init__(archive, options, include)
        self.scene_id = 0
        self.scenes: dict[str, Any] = {}
        self.models: dict[int, bop.ObjectModel] = {}
        self.targets: list[dict[str, int]] = []

    def add(self, content: SequenceContent, step: Step) -> None:
        solve = content.solve
        assert solve is not None
        for obj in content.objects:
            mesh = self.mesh(obj.mesh_key)
            self.models.setdefault(obj.ycb_id, bop.ObjectModel(obj.ycb_id, mesh.vertices,
                                                               mesh.faces))
        models = {o.ycb_id: self.models[o.ycb_id] for o in content.objects}
        with_frames = bool(self.options.get("frames"))
        for view in content.views:
            self.scene_id += 1
            cam = view.camera
            writer = bop.BopSceneWriter(self.archive.write, self.scene_id,
                                        bop.SceneCamera(cam.K, cam.T_cam_to_world, cam.width,
                                                        cam.height), models)
            frames = _Frames(self, view) if with_frames else None
            for f in range(content.num_frames):
                posed = [o for o in content.objects
                         if np.isfinite(solve.arrays["object_poses"][o.index, f]).all()]
                poses = [(o.ycb_id, solve.arrays["object_poses"][o.index, f]) for o in posed]
                notes = [trust.object_fields(content, o.index, f) for o in posed]
                depth = rgb = None
                if frames is not None:
                    rgb = frames.color(f)
                    raw = frames.depth(f)
                    depth = (None if raw is None else
                             cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED))
                writer.add_image(f, seg_of(self, content, view, f), poses, depth=depth, rgb=rgb,
                                 notes=notes)
                self.frames_written += 1
            writer.close()
            self.targets.extend(writer.targets)
            self.scenes[f"{self.scene_id:06d}"] = {
                "sequence_id": content.sequence_id, "subject": content.subject,
                "sequence": content.name, "serial": view.serial}
            step()

    def finish(self) -> None:
        bop.write_models(self.archive.write, self.models.values())
        bop.write_targets(self.archive.write, self.targets)
        self.archive.write("scenes.json", jsonfmt.document_bytes(self.scenes))
