"""Free fall (McGinnis, Perkins & King 2012): in flight the body origin (centre of mass) moves
under gravity alone, ``a = g``, so its specific force ``f = a - g`` is zero.
"""

from __future__ import annotations

import numpy as np

from . import custom_factor, vector_at


def free_fall_residual(specific_force_b_mps2):
    """``f`` (N, 3) and ``{'f': I}``."""
    f = np.atleast_2d(np.asarray(specific_force_b_mps2, dtype=float))
    return f.copy(), {"f": np.broadcast_to(np.eye(3), (f.shape[0], 3, 3))}


def make_free_fall_factor(key_specific_force: int, noise_model):
    def error(values):
        r, j = free_fall_residual(vector_at(values, key_specific_force))
        return r[0], [j["f"][0]]

    return custom_factor(noise_model, [key_specific_force], error)
