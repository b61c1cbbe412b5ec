"""Closed-form solutions for measuring a run's error.

A solution gives, for particles at initial positions ``X`` (n, d) [m] and a
time ``t`` [s], the exact displacement [m], velocity [m/s] and velocity
gradient [1/s] (which seed the particles' ``v`` and ``C``), and, for a
manufactured solution, the body force per unit mass [m/s^2] that makes it
exact. The material law each holds for is written out below; the
validation of a scene checks that its body uses it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class _CosineMode:
    """The n-th cosine mode (``mode``) of a free layer: k = n pi / extent,
    across the initial coordinate xi = X[:, across] - lo; ``_layer`` names
    the extent's and the coordinate's fields."""

    _layer: tuple[str, str]
    mode: int  # fields of the subclasses
    lo: float
    has_body_force = False

    @property
    def k(self) -> float:
        return self.mode * math.pi / getattr(self, self._layer[0])

    def _profile(self, X):
        """cos(k xi), sin(k xi)."""
        xi = X[:, getattr(self, self._layer[1])] - self.lo
        return np.cos(self.k * xi), np.sin(self.k * xi)


@dataclass(frozen=True)
class VibratingBar(_CosineMode):
    """Free-free elastic bar vibrating along ``axis`` in its n-th mode, small
    amplitude, Poisson's ratio 0 (so the bar is one-dimensional):

        u(X, t) = (v0 / omega) cos(k xi) sin(omega t) e_axis,
        v(X, t) = v0 cos(k xi) cos(omega t) e_axis,
        k = n pi / L, omega = k c, c = sqrt(E / rho), xi = X_axis - lo.

    It solves rho u_tt = E u_xx with u_x = 0 at both ends (traction free);
    the finite-strain material adds an error of order (v0 / c)^2.
    """

    name = "vibrating_bar"
    _layer = ("length", "axis")
    lo: float  # [m] the bar's end at the lower coordinate
    length: float  # [m]
    wave_speed: float  # [m/s]
    amplitude: float  # [m/s] v0
    mode: int = 1
    axis: int = 0

    @property
    def omega(self) -> float:
        """Angular frequency [rad/s]."""
        return self.k * self.wave_speed

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:
        u = np.zeros_like(X, dtype=np.float64)
        u[:, self.axis] = self.amplitude / self.omega * self._profile(X)[0] * math.sin(self.omega * t)
        return u

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        v = np.zeros_like(X, dtype=np.float64)
        v[:, self.axis] = self.amplitude * self._profile(X)[0] * math.cos(self.omega * t)
        return v

    def velocity_gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        """dv/dx at t (exact at t = 0, where x = X)."""
        n, d = X.shape
        L = np.zeros((n, d, d))
        L[:, self.axis, self.axis] = -self.amplitude * self.k * self._profile(X)[1] * math.cos(self.omega * t)
        return L

    def scales(self) -> tuple[float, float]:
        """Amplitudes of displacement [m] and velocity [m/s]."""
        return self.amplitude / self.omega, self.amplitude


@dataclass(frozen=True)
class Vortex:
    """Generalised vortex (a manufactured solution used to verify total
    Lagrangian MPM, de Vaucorbeil et al. 2020): a ring Ri <= R <= Ro about
    ``center`` whose material points turn by

        alpha(R, t) = A g(R) sin(omega t),  g = (1 - s^2)^2,  s = (R - Rm) / h,

    Rm = (Ri + Ro) / 2, h = (Ro - Ri) / 2, so the radius is kept (J = 1) and
    the rims neither move nor shear (g = g' = 0 there: traction free). For a
    neo-Hookean solid at J = 1 the Cauchy stress is mu (B - I): with the
    shear gamma = R dalpha/dR, sigma_rr = 0, sigma_rt = mu gamma,
    sigma_tt = mu gamma^2, and the body force b = a - div(sigma) / rho is

        b_r = -R alpha_t^2 + (mu / rho) gamma^2 / R,
        b_t =  R alpha_tt - (mu / rho) (dgamma/dR + 2 gamma / R),

    in the polar directions at the current angle Theta + alpha.
    """

    center: tuple[float, float]  # [m]
    inner_radius: float  # [m]
    outer_radius: float  # [m]
    shear_modulus: float  # [Pa] mu of the neo-Hookean ring
    density: float  # [kg/m^3]
    amplitude: float = 1.0  # [rad] A
    omega: float = math.pi  # [rad/s]
    name = "vortex"
    has_body_force = True

    def _polar(self, X):
        d = X - np.asarray(self.center)
        return np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])

    def _g(self, R):
        """g, dg/dR, d2g/dR2."""
        h = 0.5 * (self.outer_radius - self.inner_radius)
        s = (R - 0.5 * (self.outer_radius + self.inner_radius)) / h
        return (1 - s**2) ** 2, -4 * s * (1 - s**2) / h, (12 * s**2 - 4) / h**2

    def _angle(self, X, t):
        R, Theta = self._polar(X)
        g = self._g(R)[0]
        return R, Theta + self.amplitude * g * math.sin(self.omega * t), g

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:
        R, theta, _ = self._angle(X, t)
        x = np.asarray(self.center) + R[:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)
        return x - X

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        R, theta, g = self._angle(X, t)
        speed = R * self.amplitude * g * self.omega * math.cos(self.omega * t)  # R alpha_t
        return speed[:, None] * np.stack([-np.sin(theta), np.cos(theta)], 1)

    def velocity_gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        """dv/dx at t = 0 (x = X): v = A w(t) g(r) (-y, x) about the centre,
        so dv/dx = A w (g W + g'/r (-y, x) (x, y)^T), W the unit rotation."""
        if t != 0.0:
            raise ValueError("the vortex's velocity gradient is given at t = 0 only")
        d = X - np.asarray(self.center)
        R = np.hypot(d[:, 0], d[:, 1])
        g, dg, _ = self._g(R)
        rate = self.amplitude * self.omega
        tangent = np.stack([-d[:, 1], d[:, 0]], 1)
        W = np.array([[0.0, -1.0], [1.0, 0.0]])
        return rate * (g[:, None, None] * W + (dg / R)[:, None, None] * tangent[:, :, None] * d[:, None, :])

    def body_force(self, X: np.ndarray, t: float) -> np.ndarray:
        """Body force per unit mass [m/s^2] on the particles that started at X."""
        R, theta, _ = self._angle(X, t)
        g, dg, d2g = self._g(R)
        A, w = self.amplitude, self.omega
        s, c = math.sin(w * t), math.cos(w * t)
        alpha_t, alpha_tt = A * g * w * c, -A * g * w * w * s
        gamma = R * A * dg * s
        dgamma = A * s * (dg + R * d2g)
        k = self.shear_modulus / self.density
        b_r = -R * alpha_t**2 + k * gamma**2 / R
        b_t = R * alpha_tt - k * (dgamma + 2 * gamma / R)
        er = np.stack([np.cos(theta), np.sin(theta)], 1)
        et = np.stack([-np.sin(theta), np.cos(theta)], 1)
        return b_r[:, None] * er + b_t[:, None] * et

    def scales(self) -> tuple[float, float]:
        """Largest displacement [m] and speed [m/s] of the motion."""
        R = np.linspace(self.inner_radius, self.outer_radius, 1001)
        g = self._g(R)[0]
        turn = self.amplitude * g
        return float(np.max(2 * R * np.abs(np.sin(np.minimum(turn, np.pi) / 2)))), \
            float(np.max(R * turn * self.omega))


@dataclass(frozen=True)
class ShearWave(_CosineMode):
    """A decaying shear wave in a free slab of Newtonian viscous fluid
    (no gravity), velocity along ``axis``, varying across ``normal``:

        v(X, t) = A cos(k eta) exp(-nu k^2 t) e_axis,
        u(X, t) = A cos(k eta) (1 - exp(-nu k^2 t)) / (nu k^2) e_axis,
        k = n pi / H, eta = X_normal - lo, nu = viscosity / rho,

    with H the slab's thickness along ``normal``. The field is divergence-free
    and v . grad v = 0, so it solves the Navier-Stokes equations exactly; the
    shear stress eta_v dv/d(normal) vanishes on the slab's free faces, and
    the particles never move along ``normal`` (Lagrangian = Eulerian profile).
    The kinetic energy decays as exp(-2 nu k^2 t): the decay rate measures
    the viscosity."""

    name = "shear_wave"
    _layer = ("thickness", "normal")
    lo: float  # [m] the slab's face at the lower ``normal`` coordinate
    thickness: float  # [m] H
    kinematic_viscosity: float  # [m^2/s] nu
    amplitude: float  # [m/s] A
    mode: int = 1
    axis: int = 0
    normal: int = 1

    @property
    def rate(self) -> float:
        """Decay rate nu k^2 of the velocity [1/s]."""
        return self.kinematic_viscosity * self.k**2

    def displacement(self, X: np.ndarray, t: float) -> np.ndarray:
        u = np.zeros_like(X, dtype=np.float64)
        u[:, self.axis] = self.amplitude * self._profile(X)[0] * (-math.expm1(-self.rate * t)) / self.rate
        return u

    def velocity(self, X: np.ndarray, t: float) -> np.ndarray:
        v = np.zeros_like(X, dtype=np.float64)
        v[:, self.axis] = self.amplitude * self._profile(X)[0] * math.exp(-self.rate * t)
        return v

    def velocity_gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        n, d = X.shape
        L = np.zeros((n, d, d))
        L[:, self.axis, self.normal] = (-self.amplitude * self.k * self._profile(X)[1]
                                        * math.exp(-self.rate * t))
        return L

    def scales(self) -> tuple[float, float]:
        return self.amplitude / self.rate, self.amplitude


SOLUTIONS = {"vibrating_bar": VibratingBar, "vortex": Vortex, "shear_wave": ShearWave}


def rms(a: np.ndarray, b: np.ndarray) -> float:
    """E = sqrt(sum_p |a_p - b_p|^2 / n_p) (the A-ULMPM paper's eq. 36)."""
    return float(np.sqrt(np.sum((a - b) ** 2) / len(a))) if len(a) else 0.0
