"""Roll-pitch-yaw rotations and the maps between RPY-angle rates and angular velocity.

Convention (spec stewart-6ups.md): R = Rz(yaw) @ Ry(pitch) @ Rx(roll), angles in rad.
Angular velocities are expressed in the parent frame (the frame the pose is given in).
Everything is batched over leading dimensions and written component-wise, because
numpy's fixed cost per call, not arithmetic, dominates single-state calls.
"""
import numpy as np


def rpy_matrix(rpy):
    """Rotation matrices (..., 3, 3) from [roll, pitch, yaw] (..., 3)."""
    r, p, y = np.moveaxis(np.asarray(rpy, dtype=float), -1, 0)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rows = (
        cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
        sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
        -sp, cp * sr, cp * cr,
    )
    return np.stack(rows, axis=-1).reshape(np.shape(r) + (3, 3))


def rpy_rate_matrix(rpy):
    """E (..., 3, 3) with omega = E @ rpy_rate (omega in the parent frame)."""
    _, p, y = np.moveaxis(np.asarray(rpy, dtype=float), -1, 0)
    cp, sp, cy, sy = np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    zero, one = np.zeros_like(p), np.ones_like(p)
    rows = (cy * cp, -sy, zero, sy * cp, cy, zero, -sp, zero, one)
    return np.stack(rows, axis=-1).reshape(np.shape(p) + (3, 3))


def angular_velocity(rpy, rpy_rate):
    """omega (..., 3) in the parent frame from RPY angles and their rates."""
    _, p, y = np.moveaxis(np.asarray(rpy, dtype=float), -1, 0)
    dr, dp, dy = np.moveaxis(np.asarray(rpy_rate, dtype=float), -1, 0)
    cp, sp, cy, sy = np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([cy * cp * dr - sy * dp, sy * cp * dr + cy * dp, dy - sp * dr], axis=-1)


def cross(a, b):
    """Cross product over the last axis; ~5x cheaper than np.cross on small arrays."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)
