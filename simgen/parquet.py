"""simgen's Parquet files: missing values as Arrow nulls (data_schema.md), zstd, written atomically.

A NaN in a float column of a simgen table means "no value" (no projection, no visible box, no matched
ground truth). Arrow has a null for that, and pandas, polars, DuckDB and SQL count a null as missing
where they count a NaN as present, so every NaN becomes a null when a table is written.
"""
from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from homocal.files import write_atomic


def nan_to_null(table: pa.Table) -> pa.Table:
    """``table`` with every NaN of its floating-point columns replaced by a null (other columns as they are)."""
    for i, field in enumerate(table.schema):
        if pa.types.is_floating(field.type):
            column = table.column(i)
            table = table.set_column(i, field, pc.if_else(pc.is_nan(column), pa.scalar(None, field.type), column))
    return table


def write_parquet(path: str | Path, table: pa.Table) -> None:
    """Write ``table`` (NaN as null) to ``path`` atomically, zstd-compressed."""
    write_atomic(path, lambda p: pq.write_table(nan_to_null(table), p, compression="zstd"))
