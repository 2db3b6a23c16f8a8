"""Fields the benchmarks and tests plan on: ``rows`` x ``plots`` plots at ENGR's plot
and lane sizes (3 x 1 x 1.9 m plots, 0.8 m between rows, 1.5 m alleys; the paper's
field, ``common/fields/engr.toml``), not georeferenced, started at the default
corner, with no targets: the geometry alone, at any size."""

from __future__ import annotations

from common.field import FieldLayout


def engr_sized(rows: int, plots: int, name: str = "big") -> FieldLayout:
    """A field of ``rows`` x ``plots`` plots of ENGR's sizes."""
    return FieldLayout(
        name=name,
        rows=rows,
        plots_per_row=plots,
        plot_length=3.0,
        plot_width=1.0,
        plot_height=1.9,
        row_spacing=0.8,
        alley_width=1.5,
        headland_width=2.25,
        edge_width=1.4,
    )
