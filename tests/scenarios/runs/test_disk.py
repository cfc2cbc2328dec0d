"""Results on disk (issue 27 item 6): a damaged file is refused naming it, never reused;
files end with the umask's mode; two processes do not share one output folder."""
import os
import subprocess
import sys
import types

import numpy as np
import pytest

from scenarios.cosim import records
from scenarios.runs import engine, runner


def _records():
    return records.Records.of(np.arange(4.0), ["a.x"], ["m"], np.arange(4.0)[:, None] ** 2)


@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_read_records_of_a_damaged_npz_is_a_value_error_naming_the_file(tmp_path, damage):
    path = _records().save(tmp_path / "r.npz")
    data = bytearray(path.read_bytes())
    if damage == "truncate":
        data = data[:len(data) // 2]
    else:
        data[len(data) // 3] ^= 0x10        # inside the first column's data: Bad CRC-32
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="r.npz"):
        records.read_records(path)


def test_read_records_refuses_repeated_times(tmp_path):
    path = tmp_path / "r.npz"
    np.savez(path, **{"time [s]": np.array([0.0, 1.0, 1.0]), "a.x [m]": np.zeros(3)})
    with pytest.raises(ValueError, match="increasing"):
        records.read_records(path)


def _store_run(tmp_path):
    store = engine.Store(tmp_path)
    job = types.SimpleNamespace(key="k", scenario=types.SimpleNamespace(name="s"), parameters={})
    store.write(job, {"status": "ok", "record": _records(), "series": {"m": (np.arange(3.0), np.ones(3))}})
    return store


@pytest.mark.parametrize("suffix", [engine.RECORDS, ".npz"])
def test_a_cached_run_with_any_file_damaged_is_run_again(tmp_path, suffix):
    store = _store_run(tmp_path)
    assert store.status("k") == "ok"
    path = store.path("k", suffix)
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0x10
    path.write_bytes(bytes(data))
    assert store.status("k") is None and path.name in store.damaged["k"]


def test_files_end_with_the_umask_s_mode(tmp_path):
    old = os.umask(0o002)
    try:
        store = _store_run(tmp_path)
    finally:
        os.umask(old)
    modes = {p.name: p.stat().st_mode & 0o777 for p in tmp_path.iterdir()}
    assert modes == {"k.json": 0o664, "k.npz": 0o664, "k.records.npz": 0o664}, modes
    assert store.status("k") == "ok"


def test_text_is_utf8_in_an_ascii_locale(tmp_path):
    code = ("import numpy as np; from scenarios.cosim import records; "
            "records.Records.of(np.zeros(1), ['a.x'], ['\\u00b5m'], np.zeros((1, "
            f"1))).to_csv({str(tmp_path / 'r.csv')!r})")
    env = {**os.environ, "LC_ALL": "C", "PYTHONCOERCECLOCALE": "0", "PYTHONUTF8": "0"}
    subprocess.run([sys.executable, "-c", code], env=env, check=True, timeout=120)
    assert (tmp_path / "r.csv").read_bytes().startswith("time [s],a.x [\u00b5m]".encode())


def test_a_second_process_is_refused_the_output_folder_naming_the_first(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from scenarios.runs import runner; "
                               f"runner.output_folder({str(tmp_path)!r}, 'scene.toml'); print('held', flush=True); "
                               "time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(runner.OutputError, match=f"process {holder.pid}"):
            runner.output_folder(tmp_path, "scene.toml")
    finally:
        holder.kill()
        holder.wait(10)
