"""single.progress_bar: a terminal bar in a terminal; in a Jupyter kernel the notebook
form (ipywidgets) or a bar that redraws seldom, so a saved notebook does not keep every
carriage-return update (issue 39)."""
import io
import sys

from scenarios.runs import single


def test_a_bar_in_a_kernel_without_widgets_redraws_seldom(monkeypatch):
    monkeypatch.setattr(single.importlib.util, "find_spec", lambda name: None)
    plain = single.progress_bar(total=10, file=io.StringIO())
    monkeypatch.setitem(sys.modules, "ipykernel", sys)        # as in a Jupyter kernel
    kernel = single.progress_bar(total=10, file=io.StringIO())
    assert plain.mininterval == 0.1 and kernel.mininterval == single.NOTEBOOK_INTERVAL == 5.0
    plain.close()
    kernel.close()


def test_a_run_without_a_bar_imports_neither_tqdm_nor_numpy_ma_nor_with_its_fmus_cached_lxml(tmp_path):
    """A run's process without a progress bar pays for no tqdm (18 ms), nor, its FMUs unpacked
    once into the cache (scenarios.cosim.fmi), for lxml and fmpy's parse of their modelDescription."""
    import subprocess
    code = ("import sys; from scenarios.runs import runner\n"
            "runner.run_scenario('paper_manoeuvre', sys.argv[1], ci=True, progress=False, charts='none')\n"
            "print(sorted(m for m in ('tqdm', 'lxml', 'numpy.ma') if m in sys.modules))")
    said = [subprocess.run([sys.executable, "-c", code, str(tmp_path / "out")], capture_output=True, text=True,
                           check=True).stdout.strip().splitlines()[-1] for _ in range(2)]
    assert said[1] == "[]", said

