#!/usr/bin/env python3
"""An independent rigid-body simulator for an ellipsoid thrown, struck and caught: readings of four
accelerometer triads in a layout of its own. Uses numpy and scipy only, no gfimu code, so that it
checks gfimu from outside (the way another tool's recording would).

Body: a solid ellipsoid of semi-axes (a, b, c) and mass m, whose principal axes are the body axes
and whose centre of mass is the body origin; principal inertia ``I₁ = m (b² + c²) / 5`` and its
cyclic permutations. Motion, from ω₀ (default (5, 5, 5) rad/s) and the identity attitude:

1. free flight until ``impact_time_s``: no torque (Euler's equations ``I ω̇ = −ω × I ω``), every
   point of the body in free fall, so the specific force at the centre is zero;
2. an impact: a force of peak ``impact_peak_g`` × m × g0 along the world direction
   ``impact_direction_w``, shaped as half a sine over ``impact_duration_s``, through the body point
   ``impact_point_m``; its torque ``p × F`` (in B) drives Euler's equations and F/m is the specific
   force at the centre;
3. ground contact: the body rests on a support whose reaction, m g0 upward, passes through the
   centre (an idealised cradle: no torque, so the rotation is torque-free again), and the specific
   force at the centre is g0 upward, expressed in B.

ω and the attitude quaternion (scalar first, W←B) are integrated together with scipy's
``solve_ivp`` (DOP853, rtol = atol = 1e-12) over each phase separately, so that no step straddles
the start or the end of the impact. ω̇ at each sample is Euler's equation evaluated at the sample's
state. A triad at r (in B) with axes R_BS reads ``R_BSᵀ (f + ω̇ × r + ω × (ω × r))`` plus optional
white noise.

Output (:func:`write_recording`), deliberately unlike gfimu's log format:

- ``readings.csv``: ``t_ms, s1_ax, s1_ay, s1_az, s2_ax, ...``; time in milliseconds from the
  first sample, readings in g where the file's g is ``FILE_G`` = 9.8 m/s² (not 9.80665);
- ``truth.csv``: ``t_ms, wx_dps, wy_dps, wz_dps``: ω in the body axes in degrees per second;
- ``sensors.json``: the triads' positions in millimetres and their orientations as z-y-x Euler
  angles in degrees (R_BS = Rz(yaw) Ry(pitch) Rx(roll)), with the body's description.

    python3 tools/foreign_sim.py OUT_DIR [--noise-g 0.001] [--seed 3]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

FILE_G = 9.8
"""The recording's own g [m/s²]: readings.csv holds readings / FILE_G."""
G0 = 9.80665
"""Gravity of the physics [m/s²] (the impact's peak and the support's reaction)."""


@dataclass(frozen=True)
class Config:
    semi_axes_m: tuple[float, float, float] = (0.12, 0.08, 0.05)
    mass_kg: float = 1.5
    omega0_radps: tuple[float, float, float] = (5.0, 5.0, 5.0)
    rate_hz: float = 4000.0
    duration_s: float = 1.5
    impact_time_s: float = 0.4
    impact_duration_s: float = 0.004
    impact_peak_g: float = 15.0
    impact_direction_w: tuple[float, float, float] = (0.3, -0.2, 1.0)
    impact_point_m: tuple[float, float, float] = (0.06, -0.03, -0.045)
    noise_g: float = 0.0
    """White-noise std added to every reading [file g]; 0: exact readings."""
    seed: int = 3
    """Seed of the triads' layout and of the noise."""


def principal_inertia(semi_axes_m, mass_kg: float) -> np.ndarray:
    """(3,) principal moments of inertia [kg m²] of a solid ellipsoid about its centre."""
    a, b, c = (float(v) for v in semi_axes_m)
    return mass_kg / 5.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])


def triad_layout(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Four triads: (4, 3) positions [m] at 0.08-0.15 m from the centre in directions spread over
    the sphere (a tetrahedron, turned at random), and (4, 3) z-y-x Euler angles [deg] of their axes."""
    rng = np.random.default_rng(seed)
    tetra = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]) / np.sqrt(3.0)
    turn = Rotation.random(random_state=rng)
    directions = turn.apply(tetra)
    distances = np.array([0.08, 0.15, 0.11, 0.13])
    positions = directions * distances[:, None]
    euler = np.column_stack([rng.uniform(-180, 180, 4), rng.uniform(-80, 80, 4), rng.uniform(-180, 180, 4)])
    return positions, euler


def rotation_body_sensor(euler_zyx_deg) -> np.ndarray:
    """R_BS (v_body = R_BS v_sensor) of z-y-x Euler angles [deg]: Rz(yaw) Ry(pitch) Rx(roll)."""
    return Rotation.from_euler("ZYX", np.asarray(euler_zyx_deg, dtype=float), degrees=True).as_matrix()


def _quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.array([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw])


def _matrix_wb(q: np.ndarray) -> np.ndarray:
    """R_WB of unit quaternions (..., 4), scalar first."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return Rotation.from_quat(q[..., [1, 2, 3, 0]]).as_matrix()


class _Dynamics:
    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.inertia = principal_inertia(cfg.semi_axes_m, cfg.mass_kg)
        d = np.asarray(cfg.impact_direction_w, dtype=float)
        self.direction_w = d / np.linalg.norm(d)
        self.point_b = np.asarray(cfg.impact_point_m, dtype=float)

    def force_w(self, t: float) -> np.ndarray:
        """Impact force [N] in W at time t (zero outside the impact)."""
        c = self.cfg
        s = (t - c.impact_time_s) / c.impact_duration_s
        if s <= 0.0 or s >= 1.0:
            return np.zeros(3)
        return c.mass_kg * c.impact_peak_g * G0 * np.sin(np.pi * s) * self.direction_w

    def omega_dot(self, t: float, omega: np.ndarray, q: np.ndarray) -> np.ndarray:
        force_b = _matrix_wb(q).T @ self.force_w(t)
        torque = np.cross(self.point_b, force_b)
        return (torque - np.cross(omega, self.inertia * omega)) / self.inertia

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        omega, q = y[:3], y[3:]
        dq = 0.5 * _quat_multiply(q, np.concatenate([[0.0], omega]))
        return np.concatenate([self.omega_dot(t, omega, q), dq])

    def specific_force_b(self, t: float, q: np.ndarray) -> np.ndarray:
        c = self.cfg
        r_wb = _matrix_wb(q)
        if t < c.impact_time_s:
            return np.zeros(3)
        if t < c.impact_time_s + c.impact_duration_s:
            return r_wb.T @ self.force_w(t) / c.mass_kg
        return r_wb.T @ np.array([0.0, 0.0, G0])


def simulate(cfg: Config = Config()) -> dict:
    """Run the simulation; returns a dict of arrays: ``t_s`` (N,), ``omega_radps``, ``omega_dot_radps2``,
    ``quaternion_wb`` (N, 4), ``specific_force_mps2`` (N, 3, at the centre, in B), ``readings_mps2``
    (N, 4, 3, each triad in its own axes, noise included), ``positions_m`` (4, 3), ``euler_zyx_deg``
    (4, 3), ``inertia_kgm2`` (3,), and ``phase`` (N,) 0 free flight, 1 impact, 2 ground contact."""
    dyn = _Dynamics(cfg)
    n = int(round(cfg.duration_s * cfg.rate_hz))
    t = np.arange(n) / cfg.rate_hz
    t_imp, t_end_imp = cfg.impact_time_s, cfg.impact_time_s + cfg.impact_duration_s
    bounds = [0.0, t_imp, t_end_imp, max(float(t[-1]), t_end_imp)]
    y = np.concatenate([np.asarray(cfg.omega0_radps, dtype=float), [1.0, 0.0, 0.0, 0.0]])
    states = np.full((n, 7), np.nan)
    for k in range(3):
        lo, hi = bounds[k], bounds[k + 1]
        sel = (t >= lo) & ((t < hi) if k < 2 else (t <= hi))
        if hi <= lo:
            continue
        times = t[sel]
        if not times.size or times[-1] < hi:
            times = np.append(times, hi)  # the phase's end too: the next phase starts from it
        sol = solve_ivp(dyn.rhs, (lo, hi), y, method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times)
        if not sol.success:
            raise RuntimeError(f"integration failed in phase {k}: {sol.message}")
        states[sel] = sol.y[:, :np.count_nonzero(sel)].T
        y = sol.y[:, -1]
    omega = states[:, :3]
    q = states[:, 3:] / np.linalg.norm(states[:, 3:], axis=1, keepdims=True)
    omega_dot = np.array([dyn.omega_dot(tk, w, qk) for tk, w, qk in zip(t, omega, q)])
    force = np.array([dyn.specific_force_b(tk, qk) for tk, qk in zip(t, q)])
    positions, euler = triad_layout(cfg.seed)
    readings = np.empty((n, 4, 3))
    for i in range(4):
        r = positions[i]
        a_b = force + np.cross(omega_dot, r) + np.cross(omega, np.cross(omega, r))
        readings[:, i, :] = a_b @ rotation_body_sensor(euler[i])  # R_BSᵀ a_b, row-wise
    if cfg.noise_g > 0:
        rng = np.random.default_rng([cfg.seed, 1])
        readings = readings + rng.normal(0.0, cfg.noise_g * FILE_G, readings.shape)
    phase = np.where(t < t_imp, 0, np.where(t < t_end_imp, 1, 2))
    return {"t_s": t, "omega_radps": omega, "omega_dot_radps2": omega_dot, "quaternion_wb": q,
            "specific_force_mps2": force, "readings_mps2": readings, "positions_m": positions,
            "euler_zyx_deg": euler, "inertia_kgm2": dyn.inertia, "phase": phase}


def energy_and_momentum(omega_radps: np.ndarray, inertia_kgm2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) twice the kinetic energy ``ωᵀ I ω`` [J] and the squared angular momentum ``|I ω|²`` [(kg m²/s)²]."""
    h = omega_radps * inertia_kgm2
    return np.sum(omega_radps * h, axis=1), np.sum(h * h, axis=1)


def write_recording(sim: dict, out_dir: str | Path, cfg: Config = Config()) -> dict[str, Path]:
    """Write ``readings.csv``, ``truth.csv`` and ``sensors.json`` (module docstring) into ``out_dir``
    (created; existing files of those names are replaced). Returns their paths by name."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_ms = sim["t_s"] * 1e3
    n = t_ms.size
    cols = ["t_ms"] + [f"s{i + 1}_a{ax}" for i in range(4) for ax in "xyz"]
    data = np.column_stack([t_ms, (sim["readings_mps2"] / FILE_G).reshape(n, 12)])
    paths = {"readings": out / "readings.csv", "truth": out / "truth.csv", "sensors": out / "sensors.json"}
    fmt = ["%.4f"] + ["%.12e"] * 12
    np.savetxt(paths["readings"], data, delimiter=",", header=", ".join(cols), comments="", fmt=fmt)
    truth = np.column_stack([t_ms, np.rad2deg(sim["omega_radps"])])
    np.savetxt(paths["truth"], truth, delimiter=",", header="t_ms,wx_dps,wy_dps,wz_dps", comments="",
               fmt=["%.4f"] + ["%.12e"] * 3)
    sensors = {
        "length_unit": "mm", "angle_unit": "deg", "euler_convention": "ZYX intrinsic: R_body_sensor = Rz Ry Rx",
        "g_mps2": FILE_G, "reading_unit": "g",
        "body": {"shape": "ellipsoid", "semi_axes_mm": [1e3 * v for v in cfg.semi_axes_m], "mass_kg": cfg.mass_kg},
        "sensors": [{"id": f"s{i + 1}", "position_mm": [round(1e3 * v, 9) for v in sim["positions_m"][i]],
                     "euler_zyx_deg": [round(float(v), 9) for v in sim["euler_zyx_deg"][i]]} for i in range(4)],
        "config": asdict(cfg),
    }
    paths["sensors"].write_text(json.dumps(sensors, indent=2))
    return paths


def read_truth(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(t_ms (N,), ω (N, 3) [rad/s]) of a ``truth.csv`` written by :func:`write_recording`."""
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return data[:, 0], np.deg2rad(data[:, 1:4])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--noise-g", type=float, default=0.0, help="white-noise std of every reading [g] (0: exact)")
    ap.add_argument("--seed", type=int, default=Config.seed)
    ap.add_argument("--rate-hz", type=float, default=Config.rate_hz)
    ap.add_argument("--duration-s", type=float, default=Config.duration_s)
    args = ap.parse_args(argv)
    cfg = Config(noise_g=args.noise_g, seed=args.seed, rate_hz=args.rate_hz, duration_s=args.duration_s)
    paths = write_recording(simulate(cfg), args.out_dir, cfg)
    print("\n".join(str(p) for p in paths.values()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
