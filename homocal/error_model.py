"""The analytical distance-error model of the paper, Section 3.

For an image-to-ground homography H (ground Y = the second output coordinate, the forward distance)
and an image column u, the mapping of a row v is (eqs. (1)-(7))

    Y(v) = (A v + B) / (C v + D) = Offset + K / (v - v_h),
    A = h22, B = h21 u + h23, C = h32, D = h31 u + h33,  v_h = -D / C,  Offset = A / C,  K = (A v_h + B) / C.

A perturbed homography shifts the horizon by epsilon (eq. (9)); to first order the range error is
(eq. (14)) dY = K epsilon / (v - v_h)^2 and, with v - v_h = K / Y (eq. (8)), the quadratic law of eq. (17):

    dY = (epsilon / K) Y^2.

Indices h_ij are 1-based as in the paper; the arrays here are 0-based.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ColumnModel:
    """The hyperbolic range model of one image column (eq. (7)); all arrays broadcast with u.

    v_h: horizon row, pixels. K: scale factor, metres x pixels. offset: constant term, metres.
    """

    v_h: np.ndarray
    K: np.ndarray
    offset: np.ndarray

    def range_at(self, v: np.ndarray) -> np.ndarray:
        """Y(v) = Offset + K / (v - v_h), metres (eq. (7)); exact for the homography it came from."""
        return self.offset + self.K / (np.asarray(v, dtype=np.float64) - self.v_h)


def column_model(H: np.ndarray, u: float | np.ndarray) -> ColumnModel:
    """v_h, K and Offset of eqs. (2)-(7) for image column(s) u of the (3, 3) image-to-ground homography H."""
    u = np.asarray(u, dtype=np.float64)
    A = H[1, 1]
    B = H[1, 0] * u + H[1, 2]
    C = H[2, 1]
    D = H[2, 0] * u + H[2, 2]
    if C == 0:
        raise ValueError("the homography has no horizon crossing the image columns (h32 = 0)")
    v_h = -D / C  # eq. (4)
    return ColumnModel(v_h=v_h, K=(A * v_h + B) / C, offset=A / C + 0.0 * u)


def horizon_shift(H: np.ndarray, H_perturbed: np.ndarray, u: float | np.ndarray) -> np.ndarray:
    """epsilon = v_h(perturbed) - v_h (eq. (9)), pixels, at image column(s) u."""
    return column_model(H_perturbed, u).v_h - column_model(H, u).v_h


def quadratic_error(epsilon: np.ndarray, K: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Predicted range error dY = (epsilon / K) Y^2 (eq. (17)), metres.

    Y is the range measured from where the column model's Offset vanishes; for a tilted camera the
    Offset is small (about -h tan(tilt), -1.07 m for the paper's camera), so pass Y - Offset for the
    exact first-order term and the true range for the paper's form.
    """
    return np.asarray(epsilon) / np.asarray(K) * np.asarray(Y, dtype=np.float64) ** 2


def first_order_error(H: np.ndarray, H_perturbed: np.ndarray, u: float | np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Range error of a perturbed homography at true range Y (metres) on column u, to first order.

    A general trapezoid error changes Offset and K as well as the horizon. Expanding
    Y_hat = Offset' + K' / (v - v_h - epsilon) with v - v_h = K / (Y - Offset) (eq. (8)) gives

        dY ~ dOffset + (dK / K) (Y - Offset) + (epsilon / K) (Y - Offset)^2,

    whose last term is eq. (17); it dominates at range, and the linear term is why Method 1 fits
    e(d) = a d^2 + b d (eq. (19)).
    """
    m, mp = column_model(H, u), column_model(H_perturbed, u)
    y = np.asarray(Y, dtype=np.float64) - m.offset
    eps = mp.v_h - m.v_h
    return (mp.offset - m.offset) + (mp.K - m.K) / m.K * y + quadratic_error(eps, m.K, y)
