"""Two processes that find the same FMUs due build them once (fmu_src.atomic.building)."""
import subprocess
import sys
import zipfile

import fmpy

BUILD = """
import logging, pathlib, sys
logging.basicConfig(level=logging.INFO, format="%(message)s")
from fmu_src import native_build, python_build as builder
folder = pathlib.Path(sys.argv[1])
python = builder.ensure_built(["leg_sensor_fmu"], folder)
print(native_build.ensure_native(["leg_sensor_fmu"], folder / "native", python=python)["leg_sensor_fmu"])
"""


def test_two_processes_building_into_one_folder_build_each_fmu_once(tmp_path):
    """Started together on an empty folder, the second waits on the first's lock and finds
    both FMUs built: one 'building' line each in all, one native FMU both name, whole.
    Without the lock both compile (four lines) and write the same files at once."""
    started = [subprocess.Popen([sys.executable, "-c", BUILD, str(tmp_path)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True) for _ in range(2)]
    ended = [process.communicate(timeout=600) for process in started]
    assert [process.returncode for process in started] == [0, 0], [err for _, err in ended]
    said = "".join(err for _, err in ended)
    assert said.count("building the pythonfmu FMU of leg_sensor_fmu") == 1, said
    assert said.count("building the native FMI 2.0 FMU of leg_sensor_fmu") == 1, said
    paths = {out.strip() for out, _ in ended}
    assert len(paths) == 1
    path = paths.pop()
    assert zipfile.ZipFile(path).testzip() is None
    assert fmpy.read_model_description(path).modelIdentifier == "LegSensor"
