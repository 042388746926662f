"""Feeding the formats of worker.formats from a sequence's content, one sequence at a time.

Each exporter takes sequences with ``add`` (one view at a time, reporting progress through
``step``) and ends with ``finish``; what a format needs across sequences (COCO's one document,
BOP's models, DexYCB's split lists) is kept small. Frames are read from storage one at a time.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from backend.captures.assets import load_mesh
from backend.exports import trust
from backend.exports.archive import ExportArchive
from backend.exports.content import SequenceContent, ViewContent
from backend.solve.results import frame_payload
from backend.storage import LocalStorage, Storage, get_storage
from worker.formats import cvat, dexycb, dexycb_flags, dexycb_frames, jsonfmt, offimage
from worker.formats.files import encode_image, npz_bytes, yaml_text
from worker.geometry.mesh_io import Mesh
from worker.geometry.transforms import invert_pose, transform_points
from worker.hand.joints import JOINT_NAMES

Step = Callable[[], None]


# Object and hand meshes kept in memory between uses: a sequence's objects, many times over.
MESHES_KEPT = 32


class Exporter:
    def __init__(self, archive: ExportArchive, options: dict[str, Any], include: str) -> None:
        self.archive, self.options, self.include = archive, options, include
        self.storage: Storage = get_storage()
        self._meshes: dict[str, Mesh] = {}
        self.frames_written = 0

    def mesh(self, key: str) -> Mesh:
        """The mesh at ``key``, from the few most recently used (each sequence keeps its own
        models, so a cache of every mesh seen would grow with the project)."""
        mesh = self._meshes.pop(key, None)
        if mesh is None:
            mesh = load_mesh(self.storage, key)
        self._meshes[key] = mesh  # newest last
        while len(self._meshes) > MESHES_KEPT:
            del self._meshes[next(iter(self._meshes))]
        return mesh

    def add(self, content: SequenceContent, step: Step) -> None:
        raise NotImplementedError

    def finish(self) -> None:
        """Write what spans sequences (nothing by default)."""


def _seq_dir(content: SequenceContent) -> str:
    return dexycb.sequence_dir(content.subject, content.name)


def _world_meshes(exporter: Exporter, content: SequenceContent, frame: int
                  ) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """The solved hand and objects at ``frame``: world vertices, faces, seg value."""
    solve = content.solve
    assert solve is not None
    out = []
    for obj in content.objects:
        pose = solve.arrays["object_poses"][obj.index, frame]
        if np.isfinite(pose).all():
            mesh = exporter.mesh(obj.mesh_key)
            out.append((transform_points(pose, mesh.vertices), np.asarray(mesh.faces),
                        obj.ycb_id))
    if solve.hand_vertices is not None and solve.hand_faces is not None:
        verts = solve.hand_vertices[frame]
        if np.isfinite(verts).all():
            out.append((verts, solve.hand_faces, dexycb.HAND_SEG_VALUE))
    return out


def seg_of(exporter: Exporter, content: SequenceContent, view: ViewContent, frame: int
           ) -> np.ndarray:
    """The pinhole (K alone) segmentation of one view-frame from the solved meshes."""
    cam = view.camera
    w2c = invert_pose(cam.T_cam_to_world)
    meshes = [(transform_points(w2c, v), f, value)
              for v, f, value in _world_meshes(exporter, content, frame)]
    return dexycb_frames.render_seg(meshes, cam.K, cam.width, cam.height)


class _Frames:
    """A view's colour and depth frames as the export writes them: pinhole images (undistorted
    where the camera has distortion), copied or linked."""

    def __init__(self, exporter: Exporter, view: ViewContent) -> None:
        self.exporter, self.view = exporter, view
        cam = view.camera
        self.distorted = dexycb_frames.has_distortion(cam.dist)
        self.maps = (dexycb_frames.undistort_maps(cam.K, np.asarray(cam.dist), cam.width,
                                                  cam.height)
                     if self.distorted else None)

    def color(self, frame: int) -> bytes:
        data = self.exporter.storage.get_bytes(self.view.color_keys[frame])
        if self.maps is None:
            return data
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise ValueError(f"colour frame {self.view.color_keys[frame]} does not decode")
        return encode_image(".jpg", dexycb_frames.undistort_image(image, self.maps))

    def depth(self, frame: int) -> bytes | None:
        key = self.view.depth_keys[frame]
        if key is None:
            return None
        data = self.exporter.storage.get_bytes(key)
        if self.maps is None:
            return data
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ValueError(f"depth frame {key} does not decode")
        return encode_image(".png", dexycb_frames.undistort_image(image, self.maps, nearest=True))

    def local_path(self, key: str | None) -> Path | None:
        storage = self.exporter.storage
        if key is None or self.maps is not None or not isinstance(storage, LocalStorage):
            return None
        return storage.root / key

    def put(self, folder: str, frame: int) -> None:
        """Write (or link) the colour and depth frame under ``folder``."""
        names = (dexycb.color_file(frame), dexycb.depth_file(frame))
        keys = (self.view.color_keys[frame], self.view.depth_keys[frame])
        link = self.exporter.options.get("frames") == "link"
        for name, key, read in zip(names, keys, (self.color, self.depth), strict=True):
            target = self.local_path(key) if link else None
            if target is not None:
                self.exporter.archive.link(f"{folder}/{name}", target)
                continue
            data = read(frame)
            if data is not None:
                self.exporter.archive.write(f"{folder}/{name}", data)


class DexYCBExporter(Exporter):
    """The DexYCB raw layout, so that ``dexlabel import`` reads the export back."""

    def __init__(self, archive: ExportArchive, options: dict[str, Any], include: str) -> None:
        super().__init__(archive, options, include)
        self.models_written: set[str] = set()
        # Calibration files are the project's, shared by sequences (DexYCB's are per serial):
        # each is written once.
        self.calibration_written: set[str] = set()
        self.split_items: list[tuple[str, str, list[str], int | None]] = []

    def add(self, content: SequenceContent, step: Step) -> None:
        solve = content.solve
        assert solve is not None
        seq = _seq_dir(content)
        calib = f"{content.subject}_{content.name}"
        undistorted = {}
        for view in content.views:
            cam = view.camera
            coeffs = [float(c) for c in np.asarray(cam.dist if cam.dist is not None else [])]
            if dexycb_frames.has_distortion(coeffs):
                undistorted[view.serial] = coeffs
            self._once(dexycb.intrinsics_file(view.serial, cam.width, cam.height),
                               yaml_text(dexycb.intrinsics_doc(
                                   cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2],
                                   cam.width, cam.height, [0.0] * 5)).encode())
        master = content.master_serial or content.views[0].serial
        self._once(dexycb.extrinsics_file(calib), yaml_text(dexycb.extrinsics_doc(
            {v.serial: v.camera.T_cam_to_world for v in content.views}, master)).encode())
        calibs = []
        for hand in content.hands:
            name = hand.calib_name or f"{calib}_{hand.side}"
            calibs.append(name)
            # The shape the poses were solved with (a refined calibration may change it).
            solved = solve.arrays["betas"]
            betas = solved.tolist() if solved.size else (hand.betas or [])
            self._once(dexycb.mano_file(name), yaml_text(dexycb.mano_doc(betas)).encode())
        self._models(content)
        grasped = next((o.index for o in content.objects if o.grasped), 0)
        meta = dexycb.meta_doc(
            [v.serial for v in content.views], content.num_frames,
            [o.ycb_id for o in content.objects], grasped, [h.side for h in content.hands],
            calibs, calib, undistorted)
        meta.update(_dexycb_flag_meta(content))
        self.archive.write(f"{seq}/{dexycb.META_FILE}", yaml_text(meta).encode())
        self.archive.write(f"{seq}/{dexycb.POSE_FILE}", npz_bytes(_dexycb_pose(content)))
        for view in content.views:
            self._view(content, view, seq)
            step()
        self.split_items.append((content.subject, content.name,
                                 [v.serial for v in content.views],
                                 next((o.ycb_id for o in content.objects if o.grasped), None)))

    def _once(self, name: str, data: bytes) -> None:
        if name not in self.calibration_written:
            self.calibration_written.add(name)
            self.archive.write(name, data)

    def _models(self, content: SequenceContent) -> None:
        for obj in content.objects:
            if obj.name in self.models_written:
                continue
            self.models_written.add(obj.name)
            folder = obj.mesh_key.rsplit("/", 1)[0]
            names = {obj.mesh_key.rsplit("/", 1)[1], dexycb.MODEL_MTL, dexycb.MODEL_TEXTURE}
            for name in sorted(names):
                key = f"{folder}/{name}"
                if self.storage.exists(key):
                    self.archive.write(f"{dexycb.model_dir(obj.name)}/{name}",
                                       self.storage.get_bytes(key))

    def _view(self, content: SequenceContent, view: ViewContent, seq: str) -> None:
        solve = content.solve
        assert solve is not None
        arrays = solve.arrays
        frames = _Frames(self, view) if self.options.get("frames") else None
        folder = f"{seq}/{view.serial}"
        present = np.isfinite(arrays["object_poses"]).all(axis=(2, 3))
        valid = present & (solve.object_flags == "")
        for f in range(content.num_frames):
            seg = seg_of(self, content, view, f)
            # A flagged hand frame is unlabelled, as DexYCB leaves a hand it cannot label.
            hand = bool(content.hands) and solve.hand_trusted(f)
            labels = dexycb_frames.camera_frame_labels(
                view.camera.T_cam_to_world, view.camera.K, arrays["object_poses"][:, f],
                arrays["hand_pose_m"][f] if hand else None,
                arrays["hand_joints"][f] if hand else None, solve.root_joint, seg)
            labels.update(dexycb_flags.frame_flag_arrays(valid[:, f]))
            self.archive.write(f"{folder}/{dexycb.labels_file(f)}", npz_bytes(labels))
            if frames is not None:
                frames.put(folder, f)
            self.frames_written += 1

    def finish(self) -> None:
        setup = self.options.get("split")
        if setup:
            for name, lines in dexycb.split_lists(str(setup), self.split_items).items():
                self.archive.write(f"splits/{setup}_{name}.txt",
                                   "".join(f"{line}\n" for line in lines).encode())


def _dexycb_pose(content: SequenceContent) -> dict[str, np.ndarray]:
    """pose.npz: world poses (a flagged hand frame unlabelled) and the trust arrays beside."""
    solve = content.solve
    assert solve is not None
    arrays = solve.arrays
    frames = content.num_frames
    hand_ok = np.array([solve.hand_trusted(f) for f in range(frames)], dtype=bool)
    hand_pose_m = np.where(hand_ok[:, None], np.asarray(arrays["hand_pose_m"]), np.nan)[:, None]
    if not content.hands:
        hand_pose_m = hand_pose_m[:, :0]
    out = dexycb.pose_arrays(np.transpose(arrays["object_poses"], (1, 0, 2, 3)), hand_pose_m)
    out.update(dexycb_flags.pose_flag_arrays(
        solve.object_flags, solve.object_confidence,
        np.isfinite(arrays["object_poses"]).all(axis=(2, 3)), solve.hand_flags,
        solve.hand_confidence, np.isfinite(arrays["hand_joints"]).all(axis=(1, 2)),
        hand_pose_m.shape[1]))
    return out


def _dexycb_flag_meta(content: SequenceContent) -> dict[str, Any]:
    """meta.yml's added keys: the flags' reasons and the labels' provenance."""
    solve = content.solve
    assert solve is not None
    provenance = _provenance(content)
    hand_flags = solve.hand_flags if content.hands else np.full(content.num_frames, "")
    return {dexycb_flags.META_LABEL_FLAGS: dexycb_flags.flags_doc(solve.object_flags,
                                                                  hand_flags),
            dexycb_flags.META_LABEL_PROVENANCE: dexycb_flags.provenance_doc(
                provenance["hand"], provenance["objects"])}


def _provenance(content: SequenceContent) -> dict[str, Any]:
    """Per target over the clip: {"views_decided": F ints, "views": {serial: F states}}."""
    serials = [v.serial for v in content.views]
    hand = (dexycb_flags.target_provenance(
        content.provenance_states(f"hand:{content.hands[0].index}"), serials)
        if content.hands else None)
    return {"hand": hand, "objects": [dexycb_flags.target_provenance(
        content.provenance_states(f"object:{o.index}"), serials) for o in content.objects]}


def _work_entry(content: SequenceContent, w: Any) -> dict[str, Any]:
    names = list(JOINT_NAMES) if w.kind == "hand" else [
        f"landmark_{p + 1}" for p in range(len(w.keyframes))]
    dense = jsonfmt.dense_track(w.xy, w.visible)
    return {
        "assignment_id": w.assignment_id, "external_id": w.external_id,
        "worker_id": w.worker_id, "status": w.status, "task_id": w.task_id, "view": w.view,
        "serial": content.views[w.view].serial, "target_key": w.target_key, "kind": w.kind,
        "working_time_s": w.working_time_s, "edit_count": w.edit_count,
        "submitted_at": w.submitted_at.isoformat() if w.submitted_at else None, "qc": w.qc,
        "points": [{"index": p, "name": names[p] if p < len(names) else f"point_{p}",
                    "keyframes": w.keyframes[p], "dense": [row[p] for row in dense]}
                   for p in range(len(w.keyframes))],
    }


def consensus(content: SequenceContent) -> list[dict[str, Any]]:
    """The solved hand joints reprojected into every view (raw image pixels, with the view's
    distortion): per frame 21 [x, y], None where the frame is unlabelled."""
    solve = content.solve
    if solve is None or not content.hands:
        return []
    joints = np.asarray(solve.arrays["hand_joints"], dtype=np.float64)
    out = []
    for view in content.views:
        xy = view.camera.project(np.nan_to_num(joints))
        points = [xy[f].tolist() if np.isfinite(joints[f]).all() else None
                  for f in range(content.num_frames)]
        out.append({"serial": view.serial, "target_key": f"hand:{content.hands[0].index}",
                    "points": points})
    return out


class JsonExporter(Exporter):
    """One JSON document per sequence: ``<subject>/<sequence>.json``."""

    def add(self, content: SequenceContent, step: Step) -> None:
        solve = None
        if content.solve is not None:
            arrays = content.solve.arrays
            solve = {
                "run_id": content.solve.run_id, "optimiser": content.solve.optimiser,
                "finished_at": (content.solve.finished_at.isoformat()
                                if content.solve.finished_at else None),
                "hand_side": str(arrays["hand_side"]) or None,
                "betas": arrays["betas"].tolist(),
                "frames": [frame_payload(arrays, f) for f in range(content.num_frames)],
                "consensus": consensus(content),
                "provenance": {
                    "hand": (trust.target_decisions(content, f"hand:{content.hands[0].index}")
                             if content.hands else None),
                    "objects": [trust.target_decisions(content, f"object:{o.index}")
                                for o in content.objects]},
            }
        document = jsonfmt.sequence_document(
            {"id": content.sequence_id, "subject": content.subject, "name": content.name,
             "num_frames": content.num_frames, "fps": content.fps,
             "master_serial": content.master_serial},
            [{"view": i, "serial": v.serial, "width": v.camera.width,
              "height": v.camera.height, "K": v.camera.K.tolist(),
              "distortion": (np.zeros(5) if v.camera.dist is None else v.camera.dist).tolist(),
              "T_cam_to_world": v.camera.T_cam_to_world.tolist()}
             for i, v in enumerate(content.views)],
            [{"index": o.index, "ycb_id": o.ycb_id, "name": o.name, "grasped": o.grasped}
             for o in content.objects],
            [{"index": h.index, "side": h.side, "calib_name": h.calib_name, "betas": h.betas}
             for h in content.hands],
            [_work_entry(content, w) for w in content.work], solve, self.include)
        self.archive.write(f"{_seq_dir(content)}.json", jsonfmt.document_bytes(document))
        self.frames_written += content.num_frames * len(content.views)
        for _ in content.views:
            step()


class CvatExporter(Exporter):
    """One CVAT for video 1.1 document per sequence and view: ``<subject>/<sequence>/<serial>.xml``,
    one track per assignment (target) in that view."""

    def add(self, content: SequenceContent, step: Step) -> None:
        labels = [cvat.hand_label("hand")] + [cvat.object_label(f"object {o.index} {o.name}")
                                              for o in content.objects]
        label_of = {f"hand:{h.index}": "hand" for h in content.hands}
        label_of.update({f"object:{o.index}": f"object {o.index} {o.name}"
                         for o in content.objects})
        for v, view in enumerate(content.views):
            with self.archive.open(f"{_seq_dir(content)}/{view.serial}.xml") as out, \
                    cvat.CvatVideoWriter(out, labels, num_frames=content.num_frames,
                                         width=view.camera.width, height=view.camera.height,
                                         name=f"{content.subject}/{content.name}/{view.serial}",
                                         task_id=content.sequence_id) as writer:
                outside = trust.outside_tracks(content, view) if content.hands else None
                for w in content.work:
                    if w.view == v and w.target_key in label_of:
                        points: list[list[Any]] = list(w.keyframes)
                        if w.kind == "hand" and outside is not None:
                            # A joint the solve places outside the image is outside, not
                            # held at the border where the page had to store it.
                            points = [list(offimage.mark_outside(kfs, outside[:, p]))
                                      for p, kfs in enumerate(points)]
                        writer.add_track(label_of[w.target_key], points)
            self.frames_written += content.num_frames
            step()
