"""The cache of unpacked FMUs (scenarios.cosim.fmi.unpack): an FMU's bytes name its entry,
so a changed FMU is never served a stale one; a damaged entry is made again, not trusted;
processes that fill it at once agree; a run through it is the run without it, bit for bit."""
import io
import os
import pathlib
import subprocess
import sys
import time
import zipfile
import zlib

import numpy as np
import pytest

import movingbase
from fmu_src.native_build import ensure_native
from scenarios.cosim import fmi


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache of this test's own; unpack's per-process memo cleared around it."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(fmi.CACHE, str(folder))
    fmi.unpack.cache_clear()
    yield folder
    fmi.unpack.cache_clear()


@pytest.fixture(scope="module")
def built():
    """Two of the kit's native FMU files (build/, made if missing or stale)."""
    return ensure_native(["leg_sensor_fmu", "telescope_fmu"])


def _entries(cache):
    return sorted(p.name for p in cache.iterdir())


def _with_start(path, out, name, start):
    """A copy of the FMU ``path`` at ``out`` whose modelDescription gives variable ``name``
    the start value ``start``: the same FMU otherwise, as a rebuild with another default."""
    with zipfile.ZipFile(path) as archive:
        members = {m.filename: archive.read(m) for m in archive.infolist()}
    xml = members["modelDescription.xml"].decode()
    at = xml.index(f'name="{name}"')
    head, tail = xml[:at], xml[at:]
    old = tail[tail.index('start="'):].split('"')[1]
    members["modelDescription.xml"] = (head + tail.replace(f'start="{old}"', f'start="{start}"', 1)).encode()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for member, data in members.items():
            archive.writestr(member, data)
    return old


def _start(description, name):
    return next(v.start for v in description.modelVariables if v.name == name)


def test_a_changed_fmu_is_not_served_from_the_stale_entry(built, cache, tmp_path):
    path = tmp_path / "Sensor.fmu"
    path.write_bytes(pathlib.Path(built["leg_sensor_fmu"]).read_bytes())
    md, folder = fmi.unpack(path)
    assert md.modelName == "LegSensor" and pathlib.Path(folder).parent.parent == cache
    old = _with_start(built["leg_sensor_fmu"], tmp_path / "edited.fmu", "rate_cutoff", "123.5")
    assert float(old) != 123.5
    os.replace(tmp_path / "edited.fmu", path)                 # rebuilt in place, one default changed
    fmi.unpack.cache_clear()                                   # (a new process)
    edited, edited_folder = fmi.unpack(path)
    assert _start(edited, "rate_cutoff") == "123.5" and _start(md, "rate_cutoff") == old
    assert edited_folder != folder
    assert 'start="123.5"' in (pathlib.Path(edited_folder) / "modelDescription.xml").read_text()
    path.write_bytes(pathlib.Path(built["telescope_fmu"]).read_bytes())   # another FMU at the same path
    fmi.unpack.cache_clear()
    other, other_folder = fmi.unpack(path)
    assert other.modelName == "Telescope" and (pathlib.Path(other_folder) / "binaries/linux64/Telescope.so").is_file()
    assert len(_entries(cache)) == 3


def _damage_library(entry):
    so = entry / "fmu" / "binaries" / "linux64" / "LegSensor.so"
    so.write_bytes(so.read_bytes()[:1000])                     # truncated


def _flip_a_byte(entry):
    so = entry / "fmu" / "binaries" / "linux64" / "LegSensor.so"
    data = bytearray(so.read_bytes())
    data[len(data) // 2] ^= 0xFF                               # same size, other bytes
    so.write_bytes(bytes(data))


def _flip_a_byte_keeping_its_time(entry):
    """As bit rot, or a copy that keeps the times: only the binary's CRC-32 tells."""
    so = entry / "fmu" / "binaries" / "linux64" / "LegSensor.so"
    stat = so.stat()
    _flip_a_byte(entry)
    os.utime(so, ns=(stat.st_atime_ns, stat.st_mtime_ns))


def _edit_a_source(entry):
    source = next((entry / "fmu" / "sources").glob("*.c"))
    time.sleep(0.05)                                           # a clock tick after it was written (mtime)
    source.write_text(source.read_text().replace("(", "[", 1))   # same size, other text


@pytest.mark.parametrize("damage", [
    _damage_library, _flip_a_byte, _flip_a_byte_keeping_its_time, _edit_a_source,
    lambda entry: (entry / "description.pickle").write_bytes(b"not a pickle"),
    lambda entry: (entry / "manifest.json").unlink(),
    lambda entry: (entry / "fmu" / "modelDescription.xml").unlink(),
    lambda entry: [p.unlink() for p in entry.rglob("*") if p.is_file()],   # a foreign, empty one
], ids=["truncated", "flipped", "rot", "source", "pickle", "manifest", "member", "emptied"])
def test_a_damaged_entry_is_made_again_not_trusted(built, cache, damage):
    path = built["leg_sensor_fmu"]
    md, folder = fmi.unpack(path)
    entry = pathlib.Path(folder).parent
    damage(entry)
    fmi.unpack.cache_clear()
    again, again_folder = fmi.unpack(path)
    assert again_folder == folder and again.guid == md.guid and len(again.modelVariables) == len(md.modelVariables)
    with zipfile.ZipFile(path) as archive:                    # every member whole again
        assert any(m.filename.startswith("sources/") for m in archive.infolist())
        for member in archive.infolist():
            if not member.is_dir():
                assert zlib.crc32((entry / "fmu" / member.filename).read_bytes()) == member.CRC, member.filename
    assert _entries(cache) == [entry.name]                    # the damaged one is gone, nothing half-made left


def test_an_unwritable_cache_unpacks_for_the_process_alone(built, tmp_path, monkeypatch):
    (tmp_path / "file").write_text("a file where the cache's folder would be")
    monkeypatch.setenv(fmi.CACHE, str(tmp_path / "file" / "cache"))
    fmi.unpack.cache_clear()
    try:
        md, folder = fmi.unpack(built["leg_sensor_fmu"])
    finally:
        fmi.unpack.cache_clear()
    assert md.modelName == "LegSensor" and pathlib.Path(folder).name.startswith("movingbase-fmu-")


def test_processes_filling_the_cache_at_once_agree(built, cache):
    """Four processes unpack the same FMU into the empty cache at the same time: one entry,
    the same folder for each, no part left."""
    code = ("import sys, time; from scenarios.cosim import fmi\n"
            "time.sleep(max(0.0, float(sys.argv[2]) - time.time()))\n"
            "md, folder = fmi.unpack(sys.argv[1]); print(folder, md.guid)")
    at = str(time.time() + 3.0)                               # after every process's imports
    started = [subprocess.Popen([sys.executable, "-c", code, str(built["telescope_fmu"]), at], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True) for _ in range(4)]
    said = [p.communicate(timeout=120) for p in started]
    assert all(p.returncode == 0 for p in started), [err for _, err in said]
    assert len({out for out, _ in said}) == 1 and len(_entries(cache)) == 1


def test_a_run_through_the_cache_is_the_run_without_it_bit_for_bit(cache, monkeypatch):
    def ran():
        fmi.unpack.cache_clear()
        return movingbase.run("paper_manoeuvre", ci=True, progress=False, set={"stop_time": "2.1 s"})
    monkeypatch.setenv(fmi.CACHE, "off")
    alone = ran()
    monkeypatch.setenv(fmi.CACHE, str(cache))
    filled, reused = ran(), ran()                              # the entries made, then read
    assert len(_entries(cache)) == len(alone.scenario.fmus)
    for run in alone:
        for other in (filled[run.label], reused[run.label]):
            assert other.records.header == run.records.header and len(run.time) > 100
            assert np.asarray(other.values).tobytes() == np.asarray(run.values).tobytes()
            assert other.metrics == run.metrics


def test_check_file_reads_the_listing_of_the_bytes_it_is_given(built, tmp_path):
    """unpack reads an FMU file once: the listing it checks is of the bytes it unpacks."""
    data = pathlib.Path(built["leg_sensor_fmu"]).read_bytes()
    fake = tmp_path / "LegSensor.fmu"
    fake.write_text("not a zip")
    assert [m.filename for m in fmi.check_file(fake, data)] == zipfile.ZipFile(io.BytesIO(data)).namelist()
