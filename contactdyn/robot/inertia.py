"""Inertia data of a URDF's links: checked, repaired to the nearest valid body, or trusted.

Checks beyond Pinocchio's (which accepts all of these silently), per link: mass ≥ 0 [kg]; a
zero mass only with a zero rotational inertia (a massless frame link such as ``tip``); for a
massive link the rotational inertia about the COM is positive semi-definite and its principal
moments satisfy the triangle inequality I1 + I2 ≥ I3 (zero moments are accepted: point masses
and thin rods are idealizations; relative tolerance 1e-6 for rounded file values).

``robot.inertia`` chooses what a failure does: ``"check"`` (default) raises, ``"repair"``
replaces the inertia by the nearest valid one (Frobenius norm: same principal axes, the
principal moments projected onto the valid ones; a zero-mass link loses its rotational
inertia) and reports every change, ``"trust"`` keeps the file's values with a
warning. A negative or non-finite mass is never repaired.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..errors import RobotError

__all__ = ["INERTIA_MODES", "check_inertias", "nearest_valid_moments"]

INERTIA_MODES = ("check", "repair", "trust")
_RTOL = 1e-6  # URDF values are rounded to a few digits; exact equalities may break by this much
_KEYS = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")


def _number(element: ET.Element | None, key: str, where: str) -> float:
    text = element.get(key, "0") if element is not None else "0"
    try:
        return float(text)
    except ValueError:
        raise RobotError(f"{where}: {key} must be a number, found {text!r}") from None


_TRIANGLES = np.array([[1.0, 1.0, -1.0], [1.0, -1.0, 1.0], [-1.0, 1.0, 1.0]])  #: Ii + Ij − Ik ≥ 0


def nearest_valid_moments(moments: np.ndarray, iterations: int = 500) -> np.ndarray:
    """The nearest principal moments (Euclidean) with every I ≥ 0 and Ii + Ij ≥ Ik (Dykstra's projections).

    The valid moments are the intersection of the positive orthant and three half-spaces;
    Dykstra's algorithm converges to the projection onto it. With the same principal axes
    this is the nearest valid inertia in the Frobenius norm (the set is invariant under
    permutations, so the nearest matrix shares the eigenvectors).
    """
    m = np.asarray(moments, float).copy()
    if np.all(m >= 0.0) and np.all(_TRIANGLES @ m >= 0.0):
        return m
    corrections = np.zeros((4, 3))
    for _ in range(iterations):
        previous = m.copy()
        y = m + corrections[0]
        m = np.maximum(y, 0.0)
        corrections[0] = y - m
        for k, a in enumerate(_TRIANGLES, start=1):
            y = m + corrections[k]
            m = y - min(float(a @ y), 0.0) / 3.0 * a  # |a|² = 3
            corrections[k] = y - m
        if np.abs(m - previous).max() <= 1e-15 * max(np.abs(m).max(), 1e-300):
            break
    m = np.maximum(m, 0.0)
    m[m < 1e-12 * np.abs(moments).max()] = 0.0  # round-off of the projections
    return m


def _problem(mass: float, inertia: np.ndarray) -> str | None:
    """What is wrong with a link's inertial, or None."""
    if mass == 0.0:
        if np.any(inertia != 0.0):
            return f"zero mass [kg] with a non-zero rotational inertia {inertia.tolist()} [kg·m²]"
        return None
    eig = np.linalg.eigvalsh(inertia)  # ascending
    tol = _RTOL * max(abs(eig).max(), 1e-300)
    moments = [float(f"{e:.6g}") for e in eig]
    if eig[0] < -tol:
        return f"rotational inertia is not positive (semi-)definite: principal moments {moments} [kg·m²]"
    if eig[0] + eig[1] < eig[2] - tol:
        return (f"principal moments {moments} [kg·m²] violate the triangle inequality "
                f"I1 + I2 >= I3 ({eig[0] + eig[1]:.6g} < {eig[2]:.6g}): no rigid body has this inertia")
    return None


def _repaired(mass: float, inertia: np.ndarray) -> np.ndarray:
    if mass == 0.0:
        return np.zeros((3, 3))
    eig, axes = np.linalg.eigh(inertia)
    return axes @ np.diag(nearest_valid_moments(eig)) @ axes.T


def check_inertias(root: ET.Element, path: Path, mode: str = "check") -> list[str]:
    """Check every link's inertial (see the module docstring); return the notes of repairs or trusts.

    With ``mode = "repair"`` the ``<inertia>`` elements of ``root`` are rewritten in place.
    """
    notes = []
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        where = f"{path}: link {link.get('name')!r}"
        mass = _number(inertial.find("mass"), "value", where)
        el = inertial.find("inertia")
        xx, yy, zz, xy, xz, yz = (_number(el, k, where) for k in _KEYS)
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.isfinite(mass) or mass < 0.0:
            raise RobotError(f"{where}: mass must be >= 0 [kg], found {mass}")
        if not np.all(np.isfinite(inertia)):
            raise RobotError(f"{where}: rotational inertia must be finite [kg·m²], found {inertia.tolist()}")
        problem = _problem(mass, inertia)
        if problem is None:
            continue
        if mode == "check":
            raise RobotError(f"{where}: {problem}; set robot.inertia = \"repair\" (nearest valid inertia, "
                             "every change reported) or \"trust\" (use it as it is)")
        if mode == "trust":
            notes.append(f"link {link.get('name')!r}: {problem} (trusted as it is)")
            continue
        fixed = _repaired(mass, inertia)
        if el is None:
            el = ET.SubElement(inertial, "inertia")
        for key, value in zip(_KEYS, (fixed[0, 0], fixed[1, 1], fixed[2, 2], fixed[0, 1], fixed[0, 2], fixed[1, 2]),
                              strict=True):
            el.set(key, repr(float(value)))
        change = float(np.linalg.norm(fixed - inertia))
        notes.append(f"link {link.get('name')!r}: {problem}; repaired to principal moments "
                     f"{[float(f'{e:.6g}') for e in np.linalg.eigvalsh(fixed)]} [kg·m²] "
                     f"(change {change:.3g} kg·m², {change / max(np.linalg.norm(inertia), 1e-300):.2%})")
    return notes
