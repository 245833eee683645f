"""The shape of a critical point's null vector: its Legendre mode on a spherical reference.

A uniformly inflated sphere bifurcates into the axisymmetric modes P_n(cos Theta) (MODEL.md
section 7). The mode of a discrete bifurcation point is read from its null vector phi0: the
normal displacement it gives each node of the reference sphere is projected onto the Legendre
polynomials, and the n that carries most of it is the mode.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import legendre

from snapmem.model.scene import Scene

#: Modes tried: P_0 .. P_MAX_MODE.
MAX_MODE = 24


def sphere_reference(scene: Scene):
    """(polar angle Theta of each node [rad], the reference radius [m]) if the scene's reference
    meridian is a half circle from pole to pole about a point of the axis, else None."""
    m = scene.meridian
    r, z = m.r, m.z
    if m.closed or r[0] != 0.0 or r[-1] != 0.0:
        return None
    centre, R = 0.5 * (z[0] + z[-1]), 0.5 * abs(z[-1] - z[0])
    if R <= 0 or np.max(np.abs(np.hypot(r, z - centre) - R)) > 1e-9 * R:
        return None
    return np.arccos(np.clip((z - centre) / R * np.sign(z[-1] - z[0]), -1.0, 1.0)), R


def mode_spectrum(scene: Scene, phi: np.ndarray) -> np.ndarray | None:
    """Fractions of the null vector's normal displacement carried by P_0 .. P_MAX_MODE (they sum
    to at most 1), or None if the reference is not a sphere.

    ``phi`` : (n_free,) or (2N,) a displacement of the free degrees of freedom (or of all).
    The rigid translation (the area-weighted mean of phi_z, zero for every pure mode n >= 2 and
    what a held pole adds to keep itself in place) is removed first. The normal displacement u_n = phi_r sin(Theta) + phi_z cos(Theta) of each node is projected in
    the area-weighted inner product <f, g> = sum_i w_i f_i g_i, w_i = sin(Theta_i) times the
    node's angular spacing (the pole nodes carry a quarter spacing squared, their cap's area).
    """
    ref = sphere_reference(scene)
    if ref is None:
        return None
    theta, _ = ref
    full = np.asarray(phi, float)
    if full.size != scene.meridian.q.size:        # over the free dofs (and any body or multiplier)
        full = np.zeros(scene.n_node_dofs + len(scene.bodies))
        full[scene.free] = np.asarray(phi, float)[: scene.free.size]
        full = full[: scene.n_node_dofs]
    spacing = np.gradient(theta)
    w = np.abs(np.sin(theta) * spacing)
    w[[0, -1]] = 0.125 * spacing[[0, -1]] ** 2           # the poles' caps: pi (h/2)^2 / (2 pi)
    dz = full[1::2] - (w @ full[1::2]) / w.sum()          # without the rigid translation (a held pole's gauge)
    u_n = full[0::2] * np.sin(theta) + dz * np.cos(theta)
    total = u_n @ (w * u_n)
    if total <= 0:
        return None
    x = np.cos(theta)
    fractions = np.empty(MAX_MODE + 1)
    for n in range(MAX_MODE + 1):
        P = legendre.legval(x, np.eye(n + 1)[n])
        fractions[n] = (u_n @ (w * P)) ** 2 / ((P @ (w * P)) * total)
    return fractions


def legendre_mode(scene: Scene, phi: np.ndarray) -> int:
    """The Legendre mode n of the null vector ``phi`` on a spherical reference (the P_n carrying
    most of its normal displacement), or -1 for a scene whose reference is not a sphere."""
    spectrum = mode_spectrum(scene, phi)
    return -1 if spectrum is None else int(np.argmax(spectrum))
