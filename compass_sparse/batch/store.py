"""Results that are never lost: every finished task's rows as one Parquet file
``DIR/part-*.parquet`` (written to a temporary name and renamed, so a killed batch leaves
only whole files), merged into ``DIR/results.parquet`` at the end; a rerun reads what is
finished.  Parquet needs pyarrow (the ``batch`` extra): imported where a store is used."""
from __future__ import annotations

import os
import time

import numpy as np

__all__ = ["RESULTS_FILE", "ResultStore", "read_results"]


RESULTS_FILE = "results.parquet"


# ---------------------------------------------------------------------------- storage
def _schema(rows):
    # (pyarrow: an optional extra, the batch one)
    import pyarrow as pa

    fixed = [("index", pa.int64()), ("key", pa.string()), ("params", pa.string()),
             ("status", pa.string()), ("status_code", pa.int64()), ("success", pa.bool_()),
             ("point_status", pa.string()), ("message", pa.string()),
             ("residual", pa.float64()), ("natural_residual", pa.float64()),
             ("nit", pa.int64()), ("minor_iterations", pa.int64()), ("nfev", pa.int64()),
             ("njev", pa.int64()), ("solve_time", pa.float64()), ("time", pa.float64()),
             ("start", pa.string()), ("predicted", pa.bool_()), ("parent", pa.int64()),
             ("worker", pa.string()), ("x", pa.list_(pa.float64())), ("basis", pa.binary())]
    names = {f for f, _ in fixed}
    extra = sorted({k for r in rows for k in r if k not in names})
    return pa.schema(fixed + [(k, pa.float64()) for k in extra])


class ResultStore:
    """A directory of Parquet files, one per finished task, merged at the end."""

    def __init__(self, path):
        try:
            # (pyarrow: an optional extra, the batch one)
            import pyarrow
            import pyarrow.parquet  # noqa: F401
        except ImportError:  # pragma: no cover - CI installs the extra
            raise ImportError("writing batch results needs pyarrow: pip install "
                              "'compass-sparse[batch]'") from None
        self.path = os.fspath(path)
        os.makedirs(self.path, exist_ok=True)
        self._seq = 0

    def files(self):
        names = sorted(f for f in os.listdir(self.path) if f.endswith(".parquet"))
        return [os.path.join(self.path, f) for f in names]

    def load(self) -> dict:
        """key -> row of every finished scenario on disk (first copy wins)."""
        # (pyarrow: an optional extra, the batch one)
        import pyarrow.parquet as pq

        out = {}
        for f in self.files():
            for r in pq.read_table(f).to_pylist():
                out.setdefault(r["key"], r)
        return out

    def write(self, rows):
        # (pyarrow: an optional extra, the batch one)
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not rows:
            return
        table = pa.Table.from_pylist([_storable(r) for r in rows], schema=_schema(rows))
        self._seq += 1
        name = f"part-{time.time_ns():020d}-{os.getpid()}-{self._seq:06d}.parquet"
        tmp = os.path.join(self.path, "." + name + ".tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, os.path.join(self.path, name))

    def compact(self):
        """Merge every file into results.parquet (rename first, then delete the parts: a
        kill in between leaves duplicates that load() ignores)."""
        # (pyarrow: an optional extra, the batch one)
        import pyarrow as pa
        import pyarrow.parquet as pq

        files = self.files()
        if not files:
            return
        rows = sorted(self.load().values(), key=lambda r: r["index"])
        table = pa.Table.from_pylist(rows, schema=_schema(rows))
        tmp = os.path.join(self.path, "." + RESULTS_FILE + ".tmp")
        pq.write_table(table, tmp)
        final = os.path.join(self.path, RESULTS_FILE)
        os.replace(tmp, final)
        for f in files:
            if f != final:
                os.remove(f)


def _storable(row):
    r = dict(row)
    if isinstance(r.get("x"), np.ndarray):
        r["x"] = r["x"].tolist()
    return r


def read_results(path):
    """The rows of a results directory as a pyarrow Table, ordered by scenario index."""
    rows = sorted(ResultStore(path).load().values(), key=lambda r: r["index"])
    # (pyarrow: an optional extra, the batch one)
    import pyarrow as pa

    return pa.Table.from_pylist(rows, schema=_schema(rows))
