"""The floor: a pythonfmu FMU that does nothing in doStep (for bench_fmus.py)."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class EmptyFmu(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.register_variable(Real("u", causality=Fmi2Causality.input, start=0.0))

    def do_step(self, current_time, step_size):
        return True
