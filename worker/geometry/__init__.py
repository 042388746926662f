"""Pure NumPy geometry: cameras and projection, rigid transforms, mesh I/O, rasterisation.

Arrays are float64 with batch dimensions first; see each module for frames and units.
"""

from worker.geometry.cameras import (
    CameraModel,
    camera_to_world,
    distort_normalized,
    intrinsics_matrix,
    look_at,
    pixels_to_rays,
    project_camera_points,
    project_points,
    undistort_normalized,
    world_to_camera,
)
from worker.geometry.mesh_io import Mesh, read_mesh, write_mtl, write_obj
from worker.geometry.transforms import (
    axis_angle_to_matrix,
    axis_angle_to_quaternion,
    compose_poses,
    invert_pose,
    make_pose,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quaternion_to_axis_angle,
    quaternion_to_matrix,
    transform_points,
    transform_pose_m,
)

__all__ = [
    "CameraModel",
    "Mesh",
    "axis_angle_to_matrix",
    "axis_angle_to_quaternion",
    "camera_to_world",
    "compose_poses",
    "distort_normalized",
    "intrinsics_matrix",
    "invert_pose",
    "look_at",
    "make_pose",
    "matrix_to_axis_angle",
    "matrix_to_quaternion",
    "pixels_to_rays",
    "project_camera_points",
    "project_points",
    "quaternion_to_axis_angle",
    "quaternion_to_matrix",
    "read_mesh",
    "transform_points",
    "transform_pose_m",
    "undistort_normalized",
    "world_to_camera",
    "write_mtl",
    "write_obj",
]
