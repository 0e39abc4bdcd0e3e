"""The paper's Algorithm 1 (PIC, parameter identification control) in Python, as the Rust `pic`
with its defaults (delay mode `align`, a fixed 3 N contact threshold: the Rust detector's
noise-aware threshold is the same below 0.5 N of noise). docs/compensators/python.md."""
import numpy as np
import hilcontact as hc


class PythonPic(hc.Compensator):
    estimates_contact = True

    def reset(self, ctx):
        self.ctx, self.past, self.prev, self.t = ctx, [], None, 0
        self.x, self.P = np.array([1e5, 0.0]), np.diag([1e10, 9e4])  # k̂, ĉ and their covariance
        self.Q, self.R, self.b = np.diag([100.0, 0.01]), 0.01, 0.98  # random walk, noise, forgetting

    def step(self, inp):
        S, s = self.ctx.sensor_rotation, self.ctx.sensor_origin
        f, m = S @ inp.measured_force, S @ inp.measured_moment  # sensor frame -> t
        p, v = inp.tip_position_actual, inp.tip_velocity_actual
        self.past = (self.past or [(p, v)] * (self.ctx.sensor_delay_ticks + 1))[1:] + [(p, v)]
        p0, v0 = self.past[0]  # the kinematics τ_p ago, which made f
        contact = np.linalg.norm(f) > 3.0
        if contact and self.prev is not None:  # (7)-(13): Sage-Husa filter on the increments
            e = f / np.linalg.norm(f)
            h, z = np.array([(p0 - self.prev[1]) @ e, (v0 - self.prev[2]) @ e]), (f - self.prev[0]) @ e
            P, y, d = self.P + self.Q, z - h @ self.x, (1 - self.b) / (1 - self.b ** (self.t + 1))
            self.R = (1 - d) * self.R + d * (y * y + h @ P @ h)
            K = P @ h / (h @ P @ h + self.R)
            self.x, I_KH = self.x + K * y, np.eye(2) - np.outer(K, h)
            self.P, self.t = I_KH @ P @ I_KH.T + self.R * np.outer(K, K), self.t + 1
        self.prev = (f, p0, v0) if contact else None
        (k, c), F, M = self.x, f, m
        if contact:  # align: F_act from the model and the motion since τ_p, then (21)-(28)
            e = f / np.linalg.norm(f)
            F = e * max(np.linalg.norm(f) + k * (p - p0) @ e + c * (v - v0) @ e, 0.0)
            M = m + np.cross(p - s, F) - np.cross(p0 - s, f)
        if contact and np.linalg.norm(F) > 3.0:
            e, dp = F / np.linalg.norm(F), inp.tip_position_desired - p
            Fc = e * max(F @ e + k * dp @ e + c * (inp.tip_velocity_desired - v) @ e, 0.0)
            F, M = Fc, M + np.cross(dp, Fc) + np.cross(p - s, Fc - F)
        return {"applied_force": S.T @ F, "applied_moment": S.T @ M, "stiffness_estimate": k, "damping_estimate": c}
