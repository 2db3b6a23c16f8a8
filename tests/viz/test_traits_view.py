"""The traits view's pure core: traits.csv -> plot boxes coloured by a trait, with the
value on hover; a bad file is one warning naming it and nothing drawn."""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.canopy import TRAITS
from common.field import Field, FieldLayout, build_field
from common.messages.mission import MissionPhase, MissionState
from services.traits.outputs import header
from services.viz import traits_view as tv
from services.viz.config import VizConfig
from services.viz.scene import GREY, Entry
from tests.conftest import REPO

TINY = REPO / "tests" / "data" / "tiny.toml"
HEADER = header()  # the traits writer's own header
GREY_RGBA = [*GREY, 255]


@pytest.fixture(scope="module")
def tiny() -> Field:
    """2 rows of 3 plots; plot p is at row p // 3, column p % 3 (from 0)."""
    return build_field(msgspec.toml.decode(TINY.read_bytes(), type=FieldLayout))


def line(plot: str, row: int, col: int, height: str, quality: str = "ok", **kw: str) -> str:
    values = {t: kw.get(t, "0.5") for t in TRAITS} | {"height": height}
    cells = [plot, str(row), str(col), "1", f"G{plot[-1]}", *values.values(), quality]
    return ",".join([*cells, "2026-06-01"])


def csv_text(*lines: str, header: list[str] = HEADER) -> str:
    return "\n".join([",".join(header), *lines]) + "\n"


THREE = csv_text(
    line("101", 1, 1, "1.62"),
    line("102", 1, 2, "0.40"),
    line("103", 1, 3, "0.90"),
)


def test_three_plots_are_coloured_in_the_order_of_their_values(tiny: Field) -> None:
    b = tv.plot_boxes(tv.parse(THREE, "t.csv"), tiny, "height", "t.csv")
    assert (b.lo, b.hi, b.grey) == (0.40, 1.62, 0)
    np.testing.assert_array_equal(b.colors[1], tv.viridis(np.array([0.0]))[0])
    np.testing.assert_array_equal(b.colors[0], tv.viridis(np.array([1.0]))[0])
    # viridis grows lighter (its green rises) from the lowest value to the highest
    green = b.colors[:, 1].astype(int)
    assert green[1] < green[2] < green[0]
    assert b.labels[0] == "plot 101 G1 rep 1: height 1.62 m"
    assert b.labels[1] == "plot 102 G2 rep 1: height 0.4 m"


def test_boxes_stand_on_their_plots_as_tall_as_the_canopy(tiny: Field) -> None:
    b = tv.plot_boxes(tv.parse(THREE, "t.csv"), tiny, "cover", "t.csv")
    box = tiny.plot_boxes[:3]
    np.testing.assert_allclose(b.centers[:, :2], (box[:, :2] + box[:, 3:5]) / 2)
    np.testing.assert_allclose(b.half_sizes[:, :2], (box[:, 3:5] - box[:, :2]) / 2)
    np.testing.assert_allclose(b.half_sizes[:, 2] * 2, [1.62, 0.40, 0.90])
    np.testing.assert_allclose(b.centers[:, 2] - b.half_sizes[:, 2], box[:, 2])
    # all plots alike: the middle of the map, not its dark end
    np.testing.assert_array_equal(b.colors, np.repeat(tv.viridis(np.array([0.5])), 3, axis=0))
    assert b.labels[2] == "plot 103 G3 rep 1: cover 0.5"  # unit 1: none written


def test_flagged_and_unmeasured_plots_are_grey_with_their_quality(tiny: Field) -> None:
    text = csv_text(
        line("101", 1, 1, "1.0"),
        line("102", 1, 2, "2.0"),
        line("103", 1, 3, "9.0", quality="occluded"),
        line("201", 2, 1, "", quality="no points"),
        line("202", 2, 2, "nan"),
    )
    b = tv.plot_boxes(tv.parse(text, "t.csv"), tiny, "height", "t.csv")
    assert (b.lo, b.hi, b.grey) == (1.0, 2.0, 3)  # the occluded 9 m stretches no scale
    assert [list(c) for c in b.colors[2:]] == [GREY_RGBA] * 3
    assert b.labels[2] == "plot 103 G3 rep 1: height 9 m (occluded)"
    assert b.labels[3] == "plot 201 G1 rep 1: height not measured (no points)"
    assert b.labels[4] == "plot 202 G2 rep 1: height not measured"
    assert b.half_sizes[3, 2] * 2 == pytest.approx(tv.FLAT)  # a slab on the ground


def test_labels_give_each_trait_in_its_unit_and_leave_out_what_is_empty(tiny: Field) -> None:
    text = csv_text("7,2,3,,,1.1,1,1.2,0.8,0.2,0.25,12345,0.9,ok,")
    (row,) = tv.parse(text, "t.csv")
    assert tv.label(row, "volume_hull") == "plot 7: volume_hull 0.25 m3"
    assert tv.label(row, "points") == "plot 7: points 12345"


def test_the_entries_are_the_boxes_and_a_log_line_with_the_colour_scale(tiny: Field) -> None:
    b = tv.plot_boxes(tv.parse(THREE, "t.csv"), tiny, "height", "t.csv")
    boxes, log = tv.entries(b, "height")
    assert boxes.path == "field/traits/height" and not boxes.static
    labels = [str(x) for x in boxes.item.labels.pa_array.to_pylist()]
    assert labels == b.labels
    assert len(boxes.item.colors.pa_array) == 3
    assert log.path == "mission/log"
    assert "0.4 m (purple) to 1.62 m (yellow)" in str(log.item.text.pa_array.to_pylist())


BAD = {
    "missing column": csv_text("101,1,1,1,G1,ok", header=["plot", "row", "column", "rep", "x"]),
    "text in a number": csv_text(line("101", 1, 1, "tall")),
    "not a plot": csv_text(line("101", 1, 1, "1.0"), line("901", 3, 1, "1.0")),
    "twice": csv_text(line("101", 1, 1, "1.0"), line("102", 1, 1, "1.0")),
    "row zero": csv_text(line("101", 0, 1, "1.0")),
    "short line": csv_text("101,1,1"),
    "no plot": csv_text(),
    "not utf-8": "plot,row\n\xff\n",
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_malformed_file_is_one_line_naming_it(tiny: Field, tmp_path: Path, case: str) -> None:
    path = tmp_path / "traits.csv"
    text = BAD[case]
    path.write_bytes(text.encode("latin-1") if case == "not utf-8" else text.encode())
    with pytest.raises(tv.TraitsError) as err:
        tv.load(path, tiny, "height")
    msg = str(err.value)
    assert str(path) in msg and "\n" not in msg, msg


class Drawn:
    def __init__(self) -> None:
        self.calls: list[tuple[int, list[Entry]]] = []
        self.jobs: list[Callable[[], None]] = []

    def draw(self, stamp: int, entries: list[Entry]) -> None:
        self.calls.append((stamp, entries))

    def run(self) -> None:
        while self.jobs:
            self.jobs.pop(0)()


def done(mission: str = "m1") -> MissionState:
    return MissionState(stamp_ns=5, mission=mission, phase=MissionPhase.DONE, detail="traits done")


def write(path: Path, text: str, age_s: float = 10.0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    t = time.time() - age_s
    os.utime(path, (t, t))


def test_the_watch_draws_a_settled_file_once_and_again_when_it_changes(
    tiny: Field, tmp_path: Path
) -> None:
    d = Drawn()
    watch = tv.TraitsWatch(VizConfig(), d.draw, d.jobs.append, logging.getLogger("t"))
    path = tmp_path / "m1" / "traits.csv"
    write(path, THREE)
    watch.poll(tmp_path, done())
    assert not d.jobs, "drawn before the plots are known"
    watch.field = tiny
    running = MissionState(mission="m1", phase=MissionPhase.SCANNING)
    watch.poll(tmp_path, running)
    assert not d.jobs, "drawn before the mission is done"
    write(path, THREE, age_s=0.0)
    watch.poll(tmp_path, done())
    assert not d.jobs, "read while it may still be being written"
    write(path, THREE)
    for _ in range(3):
        watch.poll(tmp_path, done())
        d.run()
    assert len(d.calls) == 1 and d.calls[0][0] == 5
    assert d.calls[0][1][0].path == "field/traits/height"
    write(path, THREE.replace("1.62", "1.7"), age_s=5.0)
    watch.poll(tmp_path, done())
    d.run()
    assert len(d.calls) == 2


def test_the_watch_warns_once_about_a_bad_file_and_draws_nothing(
    tiny: Field, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    d = Drawn()
    watch = tv.TraitsWatch(VizConfig(), d.draw, d.jobs.append, logging.getLogger("t"))
    watch.field = tiny
    path = tmp_path / "m1" / "traits.csv"
    write(path, BAD["text in a number"])
    with caplog.at_level(logging.WARNING):
        for _ in range(3):
            watch.poll(tmp_path, done())
            d.run()
    assert not d.calls
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and str(path) in warnings[0] and "'tall'" in warnings[0]


def test_the_trait_option_names_a_trait() -> None:
    assert VizConfig().trait == "height" and VizConfig().traits_file == "traits.csv"
    assert VizConfig(trait="cover").trait == "cover"
    with pytest.raises(ValueError, match="trait='colour'"):
        VizConfig(trait="colour")
