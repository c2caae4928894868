"""The progress bar: drawn in place on a stream, or one line per update to a sink."""

import io

from vcjax.runtime.progress import ProgressBar


def test_bar_draws_in_place_and_ends_the_line_once():
    s = io.StringIO()
    bar = ProgressBar(4, "job ", stream=s, width=8)
    for _ in range(4):
        bar.update("x")
    bar.close()  # idempotent after the automatic close at 4/4
    out = s.getvalue()
    assert out.count("\r") == 4 and out.endswith("\n") and out.count("\n") == 1
    assert "[########] 4/4 100%" in out and "[##------] 1/4  25%" in out


def test_sink_gets_one_plain_line_per_update():
    lines = []
    bar = ProgressBar(3, "sweep ", sink=lines.append)
    bar.update("chunk 1")
    bar.show(3, "done")
    assert len(lines) == 2 and lines[0].startswith("sweep: 1/3 chunk 1")
    assert lines[1].startswith("sweep: 3/3 done")
