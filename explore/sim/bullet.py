"""pybullet access: a quiet import and small helpers over body and visual-shape data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from explore.core import Pose, captured_output
from explore.sim.meshes import TriMesh, box_mesh, cylinder_mesh, read_mesh, sphere_mesh

with captured_output(stdout=True):  # pybullet prints its build time on import
    import pybullet as p  # noqa: E402

pybullet = p


def frame_pose(position: tuple[float, ...], quat: tuple[float, ...]) -> Pose:
    """world_T_frame of a pybullet position and quaternion (one array built, as IK calls it a million times)."""
    m = p.getMatrixFromQuaternion(quat)
    x, y, z = position
    return np.array([[m[0], m[1], m[2], x], [m[3], m[4], m[5], y], [m[6], m[7], m[8], z], [0.0, 0.0, 0.0, 1.0]])


def link_frame_pose(body: int, link: int, client: int) -> Pose:
    """world_T_link of the URDF link frame (not the inertial frame)."""
    if link == -1:
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
        world_T_com = frame_pose(pos, orn)
        info = p.getDynamicsInfo(body, -1, physicsClientId=client)
        link_T_com = frame_pose(info[3], info[4])
        return world_T_com @ np.linalg.inv(link_T_com)
    state = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=client)
    return frame_pose(state[4], state[5])


def body_aabb(body: int, client: int) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The axis-aligned box around every link of ``body`` that has a collision shape (lo, hi).

    ``p.getAABB(body)`` is the base link's alone: pybullet_data's ``table_square`` keeps its top in
    a link below an empty base, whose box is a point on the floor, so a collision pre-filter on it
    let a robot's mast pass through the tabletop.
    """
    boxes = np.array([np.ravel(p.getAABB(body, link, physicsClientId=client))
                      for link in range(-1, p.getNumJoints(body, physicsClientId=client))])
    solid = boxes[(boxes[:, 3:] - boxes[:, :3]).max(axis=1) > 0.0]  # a link without a shape is a point
    boxes = solid if len(solid) else boxes[:1]
    return tuple(boxes[:, :3].min(axis=0).tolist()), tuple(boxes[:, 3:].max(axis=0).tolist())


def body_visual_meshes(body: int, client: int) -> list[TriMesh]:
    """The visual geometry of every link of ``body`` as triangle meshes in the world frame."""
    meshes = []
    for shape in p.getVisualShapeData(body, physicsClientId=client):
        link, geom, dims, filename = shape[1], shape[2], shape[3], shape[4]
        link_T_visual = frame_pose(shape[5], shape[6])
        world_T_frame = link_frame_pose(body, link, client)  # visual frames are URDF-link relative
        world_T_visual = world_T_frame @ link_T_visual
        if geom == p.GEOM_MESH:
            name = filename.decode() if isinstance(filename, bytes) else filename
            if not name or not Path(name).is_file():
                continue
            mesh = read_mesh(name).transformed(world_T_visual, np.asarray(dims))
        elif geom == p.GEOM_BOX:
            mesh = box_mesh(np.asarray(dims)).transformed(world_T_visual)
        elif geom == p.GEOM_SPHERE:
            mesh = sphere_mesh(dims[0]).transformed(world_T_visual)
        elif geom in (p.GEOM_CYLINDER, p.GEOM_CAPSULE):
            mesh = cylinder_mesh(dims[1], dims[0]).transformed(world_T_visual)
        else:
            continue
        meshes.append(mesh)
    return meshes
