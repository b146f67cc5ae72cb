"""A small hammer-like model written with pythonfmu 0.7.0 (pinned in .ci/run),
built into an FMU by host-tools/tests/fmu_import.rs: a piston between a rear
and a front chamber, a valve that feeds the rear chamber until the piston hits
the anvil and the front chamber until it is a quarter of the stroke back (the
rear pressure then turns it round), first-order chamber filling
(venting slower than filling, by vent_ratio),
an impact with restitution, a Coulomb friction force, an external piston force
input. Its own laws, not the project's: an FMU "by another tool".

The pressures and the acceleration it outputs are their means over the
communication step (the acceleration is the step's change of velocity over
its length), as a sampled transducer behind an anti-aliasing filter reads
them: an impact inside a step shows in the acceleration of that step."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment


class PyHammer(Fmi2Slave):
    author = "hammer-monitor tests"
    description = "hammer-like cycle for the FMU import test"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=0.3, step_size=1e-4)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.supply_bar = 5.0
        self.friction_n = 0.0
        self.f_ext_n = 0.0
        self.mass_kg = 0.2
        self.area_m2 = 3e-4
        self.area_front_m2 = 3e-4
        self.stroke_m = 0.02
        self.tau_s = 2e-3
        self.vent_ratio = 1.6
        self.p_rear = 0.0
        self.p_front = 0.0
        self.p_rear_now = 0.0
        self.p_front_now = 0.0
        self.accel = 0.0
        self.x = 0.0
        self.v = 0.0
        self.impacts = 0
        self.forward = True
        for name in ["supply_bar", "friction_n", "mass_kg", "area_m2", "area_front_m2", "stroke_m", "tau_s", "vent_ratio"]:
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("f_ext_n", causality=Fmi2Causality.input))
        for name in ["p_rear", "p_front", "accel", "x", "v"]:
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        self.register_variable(Integer("impacts", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        n = 10
        dt = step_size / n
        p_s = self.supply_bar * 1e5
        v_start = self.v
        sum_r = 0.0
        sum_f = 0.0
        for _ in range(n):
            target_r, target_f = (p_s, 0.0) if self.forward else (0.0, p_s)
            tau_r = self.tau_s if target_r > self.p_rear_now else self.vent_ratio * self.tau_s
            tau_f = self.tau_s if target_f > self.p_front_now else self.vent_ratio * self.tau_s
            self.p_rear_now += (target_r - self.p_rear_now) * dt / tau_r
            self.p_front_now += (target_f - self.p_front_now) * dt / tau_f
            sum_r += self.p_rear_now
            sum_f += self.p_front_now
            force = self.p_rear_now * self.area_m2 - self.p_front_now * self.area_front_m2 + self.f_ext_n
            if self.v != 0.0:
                force -= math.copysign(self.friction_n, self.v)
            self.v += force / self.mass_kg * dt
            self.x += self.v * dt
            if self.x >= self.stroke_m and self.v > 0.0:
                self.x = self.stroke_m
                self.v = -0.3 * self.v
                self.impacts += 1
                self.forward = False
            elif not self.forward and self.x <= 0.25 * self.stroke_m and self.v < 0.0:
                # The valve switches back on the way back; the rear
                # pressure turns the piston round (no stop, no wall).
                self.forward = True
        self.p_rear = sum_r / n
        self.p_front = sum_f / n
        self.accel = (self.v - v_start) / step_size
        return True
