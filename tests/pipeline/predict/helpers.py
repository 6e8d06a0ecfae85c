"""Synthetic terrain sources and poses shared by the prediction and sequence tests."""

import numpy as np

from scipctl.core.camera import cahv_from_intrinsics
from scipctl.core.kinematics import RoverPose
from scipctl.core.transforms import RigidTransform, euler_zyx_to_matrix
from scipctl.pipeline import predict as P


def heightfield_source(h_fn, x=(-2.0, 14.0), y=(-4.0, 4.0), step=0.02, name="hf"):
    """A TerrainSource whose grid is the height field ``z = -h(x, y)`` (site frame) seen from 20 m above."""
    xs = np.arange(x[0], x[1] + 1e-9, step)
    ys = np.arange(y[0], y[1] + 1e-9, step)
    X, Y = np.meshgrid(xs, ys)
    Z = -h_fn(X, Y)
    xyz = np.stack([X, Y, Z], -1)
    C = np.array([0.5 * (x[0] + x[1]), 0.5 * (y[0] + y[1]), -20.0])
    img = np.full((8, 8), 0.5, np.float32)
    model = cahv_from_intrinsics(4.0, 4.0, 3.5, 3.5, RigidTransform(np.eye(3), C))
    return P.TerrainSource(name, "navcam", xyz, img, model, C, 0)


def flat(X, Y):
    return np.zeros_like(X)


def box_fn(boxes):
    def h(X, Y):
        out = np.zeros_like(X)
        for (x0, y0, x1, y1, hh) in boxes:
            out = np.where((X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1), np.maximum(out, hh), out)
        return out
    return h


def start_pose(x=0.0, y=0.0, yaw=0.0):
    return RoverPose(RigidTransform(euler_zyx_to_matrix(yaw, 0.0, 0.0), np.array([x, y, 0.0])), "test", 0.03, 0.005)
