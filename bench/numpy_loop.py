"""The same HIL run as a plain Python + NumPy loop, against ``hc.simulate`` (docs/performance.md
quotes it).

    python bench/numpy_loop.py [--delay 0.02] [--repeat 5] [--runs 50] [--json FILE]

The run is ``paper-table1`` with ``pida`` (``--delay``: the robot delay, s; 20 ms as
``bench/python_path.py``), the HIL loop only (no ideal reference, no metrics, no tables: the
loop is what the comparison is about). Every tick, as the core does it for this preset
(crates/core/src/{facility/model.rs, hil.rs, world.rs, body.rs, compensator/*}):

1. the facility: the robot follows the command of ``τ_r / T`` ticks ago (a delay line of
   commands; its velocity is the delayed command segment's), the rod tip meets the two walls
   with the linear law ``F = max(k·d + c·ḋ, 0)``, the sensor reads the wrench on the frame
   (force, moment about the sensor origin) with no delay, noise or quantisation;
2. ``pida`` (docs/compensators/pida.md, Algorithm 3) as ``compensator/pida.rs`` runs it: the
   contact detector (fixed threshold, noise estimate), the ``align`` front end (eq. 6: the
   measured force moved to the robot's position now with the identified law), the Sage-Husa
   adaptive Kalman filter of ``k̂, ĉ`` on the increments along the force (eqs. 7-13), the
   compensated force and moment (eqs. 21-28), the energy observer (``work``: the exchange
   window, carried deficit) and the ``normal`` energy controller (eqs. 14-20, 29, 30);
3. the two bodies' kick-drift step under the applied wrench (eqs. 1, 2: equal and opposite
   forces, torques about each centre of mass).

Simplified, because this preset never reaches it (each checked or stated):

- the bodies' rotation: every force of this preset is along x and acts on the line of the
  centres of mass, so the core's torques are exactly zero (``world.rs`` ``through_centre``
  drops a torque across the force that is rounding alone), its attitudes stay the identity and
  its drift is ``x += v·T``, as here; the core integrates the rotation (RK4 on the quaternion)
  when an angular velocity is not zero. The loop checks that its own torques stay below 1e-9 N·m;
- friction and the online surface fit (``surface.rs``: frictionless walls, the fit never
  declares the contact frictional), the servo lag and the plant sub-steps (``servo_frequency
  = 0``: the robot is the pure delay), the sensor delay, noise and quantisation (all 0 here),
  the ``lead`` mode and the ``paper`` observer and controller (not the defaults).

The check: the loop's rod-tip velocity, contact force and the rebound speed of each
collision (the desired tip's speed at the first tick after each contact ends) against
``hc.simulate``'s time series: the largest difference must stay below ``TOLERANCE`` of the
approach speed / peak force (it is far below: the same algorithm in another language, only
the order of some floating-point sums differs). Then both are timed (wall, median of
``--repeat`` loop runs and ``--runs`` ``hc.simulate`` runs, after one warm-up) and the ratio
printed. Nothing from ``hilcontact._core`` is used in the loop: the scenario's values are read
from its resolved JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys

import numpy as np

import hilcontact as hc

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from python_path import _timings  # noqa: E402

#: Largest difference allowed between the loop and ``hc.simulate``, as a fraction of the approach
#: speed (velocities) or of the run's peak force (forces).
TOLERANCE = 1e-6


def _vec(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


def numpy_loop(sc: dict) -> dict[str, np.ndarray]:
    """The HIL loop of the resolved scenario ``sc`` (its JSON as a dict), one row per tick:
    time (s), tip_velocity (desired, m/s, ``t``), contact_force (physical, on the rod, N,
    ``t``), applied_force (on the frame, N, ``t``), energy (J), stiffness_estimate (N/m)."""
    sim, fac, comp, con = sc["simulation"], sc["facility"], sc["compensator"], sc["contact"]
    assert comp["kind"] == "pida" and comp["delay_mode"] == "align" and comp["observer"] == "work"
    assert comp["controller"] == "normal" and con["model"] == "linear"
    assert fac["servo_frequency"] == 0.0 and fac["sensor_delay"] == 0.0 and fac["sensor_noise"] == 0.0
    assert fac["torque_noise"] == 0.0 and fac["force_resolution"] == 0.0 and fac["dissipation"] == 0.0
    assert con["friction"]["kinetic"] == 0.0 and fac["robot_repeatability"] == 0.0
    T = sim["period"]
    ticks = round(sim["duration"] / T)
    delay = round(fac["robot_delay"] / T)
    m_s, m_t = sc["servicer"]["mass"], sc["target"]["mass"]
    mu = m_s * m_t / (m_s + m_t)
    rod = _vec(sc["rod"]["tip"])
    sensor = _vec(fac["sensor_position"])
    walls = [(_vec(w["point"]), _vec(w["normal"])) for w in sc["walls"]]
    k_true = con["stiffness"] * fac["stiffness_error"]
    c_true = con["damping"] * fac["damping_error"]
    zero = np.zeros(3)
    # the bodies (world = t: the target's attitude stays the identity)
    xs, vs = _vec(sc["servicer"]["position"]), _vec(sc["servicer"]["velocity"])
    xt, vt = _vec(sc["target"]["position"]), _vec(sc["target"]["velocity"])
    assert not any(sc[b]["angular_velocity"][i] for b in ("servicer", "target") for i in range(3))

    # pida's state: the detector (two: the front end's and the amendment's), the filter, the
    # align front end's kinematics, the observer's window and previous tick
    base = comp["contact_force"]
    lam = min(T / 0.1, 1.0)  # detect.rs NOISE_TIME

    def detector() -> dict:
        return {"variance": 0.0, "free": 0, "peak": 0.0, "on": False}

    def noise(d: dict) -> float:
        if d["free"] < 1.0 / lam:
            return max(math.sqrt(d["variance"]), 0.5 * d["peak"])
        return math.sqrt(d["variance"])

    def update(d: dict, force: np.ndarray) -> bool:
        magnitude = float(np.linalg.norm(force))
        level = max(base, (4.0 if d["on"] else 6.0) * noise(d))  # OFF / ON_SIGMAS
        d["on"] = magnitude > level
        if not d["on"]:
            sample = magnitude * magnitude / 3.0
            d["free"] += 1
            if d["free"] <= 1.0 / lam:
                d["variance"] += (sample - d["variance"]) / d["free"]
                d["peak"] = max(d["peak"], magnitude)
            else:
                d["variance"] += lam * (sample - d["variance"])
        return d["on"]

    front, amend = detector(), detector()
    x = np.array([comp["stiffness_initial"], comp["damping_initial"]])
    P = np.diag([comp["stiffness_std"] ** 2, comp["damping_std"] ** 2])
    Q = np.diag([comp["stiffness_walk"] ** 2, comp["damping_walk"] ** 2])
    R, b, t_filter = comp["noise_std"] ** 2, comp["forgetting"], 0
    kinematics: list[tuple[np.ndarray, np.ndarray]] = []  # the robot tip's, newest last
    previous_sample = None  # (force, position, velocity, in_contact)
    window = {"open": False, "energy": 0.0, "carried": 0.0, "peak": 0.0}
    prev_tick = None  # (force, direction, damping, velocity, alpha_force)
    alpha_max, ratio_max = comp["alpha_max"], comp["force_ratio_max"]

    def pida(f_mea, m_mea, p_act, v_act, p_des, v_des):
        nonlocal x, P, R, t_filter, previous_sample, prev_tick
        # ContactEstimator::step, align, fresh every tick, no sensor delay
        if previous_sample is None:
            kinematics.extend([(p_act, v_act)] * (1 + 64))
        kinematics.append((p_act, v_act))
        del kinematics[0]
        p_then, v_then = kinematics[-1]  # sensor delay 0: the kinematics of now
        in_contact = update(front, f_mea)
        if in_contact and previous_sample is not None and previous_sample[3]:
            e = f_mea / np.linalg.norm(f_mea)
            h = np.array([(p_then - previous_sample[1]) @ e, (v_then - previous_sample[2]) @ e])
            z = (f_mea - previous_sample[0]) @ e
            # Sage-Husa adaptive Kalman filter (akf.rs)
            p_prior = P + Q
            y = z - h @ x
            d_t = (1.0 - b) / (1.0 - b ** (t_filter + 1.0))
            hph = h @ (p_prior @ h)
            R = (1.0 - d_t) * R + d_t * (y * y + hph)
            s = hph + R
            gain = p_prior @ h / s
            x = x + gain * y
            i_kh = np.eye(2) - np.outer(gain, h)
            P = i_kh @ p_prior @ i_kh.T + np.outer(gain, gain) * R
            t_filter += 1
        previous_sample = (f_mea, p_then, v_then, in_contact)
        k_hat, c_hat = x[0], x[1]
        if in_contact:  # eq. (6), align: the force moved to the robot's position now
            e = f_mea / np.linalg.norm(f_mea)
            increment = k_hat * ((p_act - p_then) @ e) + c_hat * ((v_act - v_then) @ e)
            magnitude = max(f_mea @ e + increment, 0.0)
            force = f_mea + e * (magnitude - f_mea @ e)
            moment = m_mea + np.cross(p_act - sensor, force) - np.cross(p_then - sensor, f_mea)
        else:
            force, moment = f_mea, m_mea
        in_contact = in_contact and np.linalg.norm(force) > max(base, 4.0 * noise(front))
        direction = force / np.linalg.norm(force) if in_contact else zero
        # compensate_force, eqs. (21)-(28)
        if in_contact:
            dp = p_des - p_act
            along = force @ direction + k_hat * (dp @ direction) + c_hat * ((v_des - v_act) @ direction)
            f_comp = direction * max(along, 0.0)
            error = f_comp - force
            m_comp = moment + np.cross(dp, f_comp) + np.cross(p_act - sensor, error)
        else:
            f_comp, m_comp = force, moment
        # DampingAmendment::step: the observer (work) and the controller (normal)
        update(amend, force)
        quiet = min(5.0 * noise(amend), max(base, 4.0 * noise(amend)))
        active = np.linalg.norm(f_comp) > quiet
        f_norm = float(np.linalg.norm(f_comp))
        obs_direction = direction if (direction @ direction > 0.5 or f_norm == 0.0) else f_comp / f_norm

        def elastic(tick) -> np.ndarray:
            f, d, c, v = tick[0], tick[1], tick[2], tick[3]
            return f - d * (max(c, 0.0) * (v @ d))

        work = 0.0
        if prev_tick is not None:
            work = 0.5 * T * ((elastic(prev_tick) + prev_tick[4]) @ (prev_tick[3] + v_des))
        if window["open"]:
            window["energy"] += work
            window["peak"] = max(window["peak"], window["energy"])
        exchange = in_contact or active
        if not window["open"] and exchange:
            window["energy"], window["carried"], window["peak"] = window["carried"], 0.0, 0.0
        elif window["open"] and not exchange:
            window["carried"] = max(min(window["energy"], 0.0), -0.02 * window["peak"])  # CARRY_SHARE
            window["energy"] = 0.0
        window["open"] = exchange
        energy = window["energy"]
        f_alpha = zero
        if exchange:
            current = (f_comp, obs_direction, c_hat, v_des, zero)
            f_ek = elastic(current)
            ctrl_direction = direction if (in_contact or f_norm == 0.0) else f_comp / f_norm
            norm = float(np.linalg.norm(f_ek))
            e_hat = f_ek / norm if norm > 1e-9 else ctrl_direction
            if energy < 0.0 and e_hat @ e_hat >= 0.5:
                v_along = v_des @ e_hat
                if v_along != 0.0:
                    alpha = min(-energy / (T * v_along * v_along), alpha_max)
                    bound = ratio_max * max(f_norm, base)
                    f_alpha = e_hat * (min(alpha * abs(v_along), bound) * math.copysign(1.0, v_along))
            prev_tick = (f_comp, obs_direction, c_hat, v_des, f_alpha)
            applied = f_comp + f_alpha
            applied_moment = m_comp + np.cross(p_des - sensor, f_alpha)
        else:
            prev_tick = (zero, obs_direction, 0.0, v_des, zero)
            applied, applied_moment = zero, zero
        return applied, applied_moment, k_hat

    out = {name: np.empty((ticks + 1, 3)) for name in ("tip_velocity", "contact_force", "applied_force")}
    out["energy"] = np.empty(ticks + 1)
    out["stiffness_estimate"] = np.empty(ticks + 1)
    # the robot: the commands of the last `delay + 1` ticks (the initial one held before)
    commands = [(xs - xt, vs - vt)] * (delay + 2)
    actual_p, actual_v = xs - xt, zero  # at rest at the initial command
    for k in range(ticks + 1):
        p_des, v_des = xs - xt + rod, vs - vt  # the command: the relative motion, its tip
        if k > 0:  # the facility follows the delayed command segment
            commands.append((xs_cmd, vs_cmd))
            del commands[0]
            a, b_ = commands[0][0], commands[1][0]
            actual_p, actual_v = b_, (b_ - a) / T
        tip = actual_p + rod
        f_rod = zero
        for point, normal in walls:
            d = -((tip - point) @ normal)
            if d > 0.0:
                f_rod = f_rod + normal * max(k_true * d + c_true * -(actual_v @ normal), 0.0)
        f_mea, m_mea = -f_rod, np.cross(tip - sensor, -f_rod)
        applied, applied_moment, k_hat = pida(f_mea, m_mea, tip, actual_v, p_des, v_des)
        out["tip_velocity"][k] = v_des
        out["contact_force"][k] = f_rod
        out["applied_force"][k] = applied
        out["energy"][k] = 0.5 * mu * ((vs - vt) @ (vs - vt))
        out["stiffness_estimate"][k] = k_hat
        # eqs. (1), (2): the wrench on the frame on the target at the sensor origin, the opposite
        # on the servicer; kick then drift (the attitudes stay the identity)
        torque_t = applied_moment + np.cross(sensor - xt, applied)
        torque_s = -applied_moment - np.cross(sensor - xs, applied)
        assert abs(torque_t).max() < 1e-9 and abs(torque_s).max() < 1e-9, "the bodies would turn"
        vs = vs - applied * (T / m_s)
        vt = vt + applied * (T / m_t)
        xs = xs + vs * T
        xt = xt + vt * T
        xs_cmd, vs_cmd = xs - xt, vs - vt
    out["time"] = np.arange(ticks + 1) * T
    return out


def rebound_speeds(time: np.ndarray, tip_velocity: np.ndarray, contact_force: np.ndarray) -> list[float]:
    """The desired tip's speed (m/s) at the first tick after each physical contact ends."""
    touching = np.linalg.norm(contact_force, axis=1) > 0.0
    ends = np.flatnonzero(touching[:-1] & ~touching[1:]) + 1
    return [float(np.linalg.norm(tip_velocity[i])) for i in ends]


def core_columns(run) -> dict[str, np.ndarray]:
    ts = run.timeseries
    vec = lambda name: ts[[f"{name}_x", f"{name}_y", f"{name}_z"]].to_numpy()  # noqa: E731
    return {
        "time": ts["time"].to_numpy(),
        "tip_velocity": vec("tip_velocity"),
        "contact_force": vec("contact_force"),
        "applied_force": vec("applied_force"),  # the sensor frame is `t` in this preset
        "energy": ts["energy"].to_numpy(),
        "stiffness_estimate": ts["stiffness_estimate"].to_numpy(),
    }


def check(loop: dict[str, np.ndarray], core: dict[str, np.ndarray], approach: float) -> dict[str, float]:
    """The largest differences between the loop and the core, as fractions; raises if one
    passes TOLERANCE or the collisions differ."""
    assert len(loop["time"]) == len(core["time"]), "the runs' lengths differ"
    peak = float(np.abs(core["contact_force"]).max())
    diffs = {
        "tip_velocity": float(np.abs(loop["tip_velocity"] - core["tip_velocity"]).max()) / approach,
        "contact_force": float(np.abs(loop["contact_force"] - core["contact_force"]).max()) / peak,
        "applied_force": float(np.abs(loop["applied_force"] - core["applied_force"]).max()) / peak,
    }
    r_loop = rebound_speeds(loop["time"], loop["tip_velocity"], loop["contact_force"])
    r_core = rebound_speeds(core["time"], core["tip_velocity"], core["contact_force"])
    assert len(r_loop) == len(r_core) > 0, f"collisions: loop {len(r_loop)}, core {len(r_core)}"
    diffs["rebound_speed"] = max(abs(a - b) for a, b in zip(r_loop, r_core)) / approach
    for name, value in diffs.items():
        assert value <= TOLERANCE, f"{name}: the loop is off by {value:.3g} (> {TOLERANCE})"
    diffs["collisions"] = len(r_core)
    diffs["rebound_speeds_core"] = r_core  # type: ignore[assignment]
    diffs["rebound_speeds_loop"] = r_loop  # type: ignore[assignment]
    return diffs


def _medians(fn, n: int) -> tuple[float, float]:
    """Median wall and CPU time (s) of ``n`` calls after one to warm up (python_path.py's
    ``_timings``): on a machine shared with other jobs the wall time measures them too, the CPU
    time of the process much less."""
    wall, cpu = _timings(fn, n)
    return statistics.median(wall), statistics.median(cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--delay", type=float, default=0.02, help="robot delay, s")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs of the NumPy loop")
    parser.add_argument("--runs", type=int, default=50, help="timed runs of hc.simulate")
    parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = parser.parse_args()
    scenario = hc.load_scenario("paper-table1", {"compensator.kind": "pida", "facility.robot_delay": args.delay})
    sc = json.loads(scenario.to_json())
    approach = float(np.linalg.norm(np.subtract(sc["servicer"]["velocity"], sc["target"]["velocity"])))
    run = hc.simulate(scenario)
    diffs = check(numpy_loop(sc), core_columns(run), approach)
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; paper-table1, pida, robot delay {args.delay * 1e3:g} ms")
    print(
        f"the NumPy loop against hc.simulate: {diffs['collisions']} collisions, rebound speeds (m/s) "
        + ", ".join(f"{v:.6f}" for v in diffs["rebound_speeds_core"])  # type: ignore[union-attr]
        + f"; largest differences: tip velocity {diffs['tip_velocity']:.1e} of the approach speed, contact force "
        f"{diffs['contact_force']:.1e} and applied force {diffs['applied_force']:.1e} of the peak force, rebound speed "
        f"{diffs['rebound_speed']:.1e} (tolerance {TOLERANCE:g})"
    )
    spin = float(np.abs(run.timeseries[[f"angular_velocity_{a}" for a in "xyz"]].to_numpy()).max())
    print(f"(hc.simulate's largest relative angular velocity: {spin:.1e} rad/s; the loop does not integrate rotation)")
    loop_wall, loop_cpu = _medians(lambda: numpy_loop(sc), args.repeat)
    core_wall, core_cpu = _medians(lambda: hc.simulate(scenario), args.runs)
    print(
        f"NumPy loop (HIL loop only): median wall {loop_wall * 1e3:.1f} ms, CPU {loop_cpu * 1e3:.1f} ms; "
        f"hc.simulate (reference, HIL loop, metrics, tables): median wall {core_wall * 1e3:.2f} ms, "
        f"CPU {core_cpu * 1e3:.2f} ms; ratio: wall {loop_wall / core_wall:.0f}, CPU {loop_cpu / core_cpu:.0f}"
    )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"numpy_loop_wall_ms": loop_wall * 1e3, "numpy_loop_cpu_ms": loop_cpu * 1e3,
                       "simulate_wall_ms": core_wall * 1e3, "simulate_cpu_ms": core_cpu * 1e3,
                       "ratio_wall": loop_wall / core_wall, "ratio_cpu": loop_cpu / core_cpu,
                       "load": os.getloadavg()[0], **diffs}, handle, indent=1)


if __name__ == "__main__":
    main()
