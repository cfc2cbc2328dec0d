"""Opening FMU instances in tests; conftest frees every one after each test (an unfreed
pythonfmu instance can corrupt the heap when the process exits)."""
from movingbase.scenarios.fmi import Instance

OPENED = []


def open_fmu(path, name="a", **values):
    """An initialised instance (start time 0) with ``values`` set in initialization mode."""
    instance = Instance(path, name)
    OPENED.append(instance)
    instance.initialize(0.0, values)
    return instance


def free_all():
    while OPENED:
        OPENED.pop().terminate()
