"""The smallest compensator: the measured wrench goes straight into the dynamics (as the
shipped `none`; with any delay in the loop it diverges)."""
import hilcontact as hc


class PassThrough(hc.Compensator):
    def step(self, inp):
        return hc.plugin.StepOutput(inp.measured_force, inp.measured_moment)
