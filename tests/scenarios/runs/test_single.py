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
