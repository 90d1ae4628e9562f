"""Particle layouts for SPEM: the TMz sets (E; Hx, Hy) of :mod:`.tmz` and the TEz sets (Hz; Ex, Ey) of :mod:`.tez`.

Examples
--------
>>> lay = yee_layout((0.0, 1.0, 0.0, 1.0), 0.25)
>>> lay.e.shape, lay.hx.shape, lay.hy.shape, int(lay.e_fixed.sum())
((25, 2), (20, 2), (20, 2), 16)
"""

from .tez import POISSON_H_RATIO, TEZ_LAYOUT_KINDS, TEzLayout, tez_disk_layout, tez_layout, wall_closure_layout
from .tmz import (
    BALANCE_EXCESS,
    BALANCE_RADIUS,
    BALANCE_RELAX,
    BALANCE_ROUNDS,
    CALM_INSET,
    CALM_RAMP,
    JITTER_H_RATIO,
    JOINT_COVER,
    JOINT_EH,
    JOINT_HH,
    JOINT_ITERATIONS,
    JOINT_WALL_MARGIN,
    LAYOUTS,
    POISSON_SBP_H_RATIO,
    Layout,
    balance_h,
    balanced_disk_layout,
    balanced_poisson_layout,
    disk_layout,
    jitter,
    joint_poisson_layout,
    line_layout,
    make_layout,
    poisson_layout,
    relax_h,
    staggered_layout,
    supported,
    yee_layout,
)

__all__ = ["LAYOUTS", "Layout", "staggered_layout", "yee_layout", "poisson_layout", "jitter", "make_layout",
           "disk_layout", "line_layout", "joint_poisson_layout", "relax_h", "balance_h", "balanced_poisson_layout",
           "balanced_disk_layout", "supported", "BALANCE_EXCESS", "BALANCE_RADIUS", "BALANCE_RELAX", "BALANCE_ROUNDS",
           "JOINT_COVER", "JOINT_EH", "JOINT_HH", "JOINT_ITERATIONS", "JOINT_WALL_MARGIN", "JITTER_H_RATIO", "POISSON_SBP_H_RATIO",
           "TEZ_LAYOUT_KINDS", "POISSON_H_RATIO", "TEzLayout", "tez_layout", "tez_disk_layout", "wall_closure_layout", "CALM_INSET",
           "CALM_RAMP"]
