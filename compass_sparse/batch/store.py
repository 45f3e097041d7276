"""Results that are never lost: every finished task's rows as one Parquet file
``DIR/part-*.parquet``, merged into ``DIR/results.parquet`` at the end; a rerun reads what
is finished.  Parquet needs pyarrow (the ``batch`` extra): imported where a store is used.

Durability.  A file is written under a temporary name of its own writer (pid and a random
token: two writers never share one), flushed to disk (fsync), renamed into place, and the
folder is flushed after the rename, so that a machine that crashes leaves either the whole
file or none of it, never a truncated one under a final name.

Damage.  A part that cannot be read (truncated by a crash of a file system that does not
keep the promise above, or written by hand) is moved to ``DIR/quarantine/`` with a warning
naming it, and its scenarios are solved again: one bad file costs its scenarios, not the
folder.  (Only the batch that holds the folder's lock moves files; :func:`read_results`
skips an unreadable file with the same warning and moves nothing.)

Readers.  Merging deletes the parts it merged, after the merged file is in place; a reader
that listed a part just deleted finds its rows in the merged file and reads the folder
again.

The folder's model.  ``DIR/model.json`` holds the fingerprint of the model whose results
these are (:mod:`compass_sparse.batch.fingerprint`) and the scenario it was taken at.
"""
from __future__ import annotations

import json
import logging
import os
import secrets
import time
import warnings
from datetime import datetime, timezone

import numpy as np

logger = logging.getLogger("compass_sparse")

__all__ = ["MODEL_FILE", "QUARANTINE", "RESULTS_FILE", "ResultStore", "read_results"]


RESULTS_FILE = "results.parquet"
MODEL_FILE = "model.json"
QUARANTINE = "quarantine"
READ_ATTEMPTS = 5
"""Listings of the folder a reader tries when parts vanish under it (merged meanwhile)."""


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


def _fsync_folder(path):
    """Flush a folder's entries (a rename is durable only then); a no-op where folders
    cannot be opened (Windows)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - Windows
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - file systems without directory fsync
        pass
    finally:
        os.close(fd)


def _fsync_file(path):
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class ResultStore:
    """A directory of Parquet files, one per finished task, merged at the end.

    ``writer``: this store may change the folder (move damaged parts aside, merge, write
    the model's fingerprint); the batch that holds the folder's lock is the writer."""

    def __init__(self, path, writer: bool = True):
        try:
            # (pyarrow: an optional extra, the batch one)
            import pyarrow
            import pyarrow.parquet  # noqa: F401
        except ImportError:  # pragma: no cover - CI installs the extra
            raise ImportError("writing batch results needs pyarrow: pip install "
                              "'compass-sparse[batch]'") from None
        self.path = os.fspath(path)
        self.writer = writer
        if writer:
            os.makedirs(self.path, exist_ok=True)
        self._seq = 0
        self._token = secrets.token_hex(4)

    def files(self):
        names = sorted(f for f in os.listdir(self.path) if f.endswith(".parquet"))
        return [os.path.join(self.path, f) for f in names]

    def _tmp(self, name):
        """A temporary name of this writer's own (pid and token: never another's)."""
        return os.path.join(self.path, f".{name}.{os.getpid()}-{self._token}.tmp")

    def _put(self, write, name):
        """write(tmp), then fsync, rename into place and flush the folder."""
        tmp = self._tmp(name)
        try:
            write(tmp)
            _fsync_file(tmp)
            os.replace(tmp, os.path.join(self.path, name))
        except BaseException:
            if os.path.exists(tmp):
                os.remove(tmp)
            raise
        _fsync_folder(self.path)

    # ------------------------------------------------------------------ reading
    def load(self) -> dict:
        """key -> row of every finished scenario on disk (first copy wins); unreadable
        files are skipped (and, by the writer, quarantined) with a warning."""
        for attempt in range(READ_ATTEMPTS):
            try:
                return self._load_once()
            except FileNotFoundError:
                # a part merged and deleted after it was listed: its rows are in the
                # merged file now; list again
                if attempt == READ_ATTEMPTS - 1:
                    raise
                time.sleep(0.05 * (attempt + 1))
        return {}  # pragma: no cover

    def _load_once(self) -> dict:
        # (pyarrow: an optional extra, the batch one)
        import pyarrow.parquet as pq

        out = {}
        for f in self.files():
            try:
                rows = pq.read_table(f).to_pylist()
            except FileNotFoundError:
                raise
            except Exception as exc:  # pyarrow's ArrowInvalid, OSError, ...: a damaged file
                self._damaged(f, exc)
                continue
            for r in rows:
                out.setdefault(r["key"], r)
        return out

    def _damaged(self, f, exc):
        what = f"unreadable results file {f} ({type(exc).__name__}: {exc})"
        if not self.writer:
            warnings.warn(f"{what}: skipped", RuntimeWarning, stacklevel=4)
            return
        qdir = os.path.join(self.path, QUARANTINE)
        os.makedirs(qdir, exist_ok=True)
        dest = os.path.join(qdir, os.path.basename(f))
        if os.path.exists(dest):
            dest += f".{time.time_ns()}"
        os.replace(f, dest)
        _fsync_folder(self.path)
        warnings.warn(f"{what}: moved to {dest}; its scenarios are solved again",
                      RuntimeWarning, stacklevel=4)
        logger.warning("batch: %s: moved to %s", what, dest)

    # ------------------------------------------------------------------ writing
    def write(self, rows):
        # (pyarrow: an optional extra, the batch one)
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not rows:
            return
        table = pa.Table.from_pylist([_storable(r) for r in rows], schema=_schema(rows))
        self._seq += 1
        name = (f"part-{time.time_ns():020d}-{os.getpid()}-{self._token}-"
                f"{self._seq:06d}.parquet")
        self._put(lambda tmp: pq.write_table(table, tmp), name)

    def compact(self):
        """Merge every file into results.parquet: the merged file is in place (fsync,
        rename) before the parts it holds are deleted, so a kill in between leaves
        duplicates, which load() ignores."""
        # (pyarrow: an optional extra, the batch one)
        import pyarrow as pa
        import pyarrow.parquet as pq

        files = self.files()
        if not files:
            return
        rows = sorted(self.load().values(), key=lambda r: r["index"])
        files = [f for f in files if os.path.exists(f)]  # (quarantined ones are gone)
        table = pa.Table.from_pylist(rows, schema=_schema(rows))
        self._put(lambda tmp: pq.write_table(table, tmp), RESULTS_FILE)
        final = os.path.join(self.path, RESULTS_FILE)
        for f in files:
            if f != final:
                os.remove(f)
        _fsync_folder(self.path)

    def clean_temporary(self):
        """Delete temporary files left by killed writers (the lock holder alone writes:
        none of them is being written)."""
        for f in os.listdir(self.path):
            if f.startswith(".") and f.endswith(".tmp"):
                try:
                    os.remove(os.path.join(self.path, f))
                except FileNotFoundError:
                    pass

    # ------------------------------------------------------------------ the model
    def model(self):
        """The folder's model record ({"fingerprint", "reference", ...}) or None."""
        p = os.path.join(self.path, MODEL_FILE)
        try:
            with open(p, encoding="utf-8") as fh:
                return json.load(fh)
        except FileNotFoundError:
            return None

    def set_model(self, fingerprint: dict, reference: dict):
        record = {"fingerprint": fingerprint, "reference": reference,
                  "written": datetime.now(timezone.utc).isoformat(timespec="seconds")}

        def write(tmp):
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(record, fh, indent=1, sort_keys=True)

        self._put(write, MODEL_FILE)

    def has_results(self) -> bool:
        return bool(self.files())

    def set_aside(self) -> str:
        """Move the folder's results and model record into a new subfolder
        ``previous-<UTC time>`` (nothing is deleted); returns its path."""
        stamp = datetime.now(timezone.utc).strftime("%Y%m%d-%H%M%S")
        dest = os.path.join(self.path, f"previous-{stamp}")
        k = 1
        while os.path.exists(dest):
            k += 1
            dest = os.path.join(self.path, f"previous-{stamp}-{k}")
        os.makedirs(dest)
        for f in self.files() + [os.path.join(self.path, MODEL_FILE)]:
            if os.path.exists(f):
                os.replace(f, os.path.join(dest, os.path.basename(f)))
        _fsync_folder(self.path)
        return dest


def _storable(row):
    r = dict(row)
    if isinstance(r.get("x"), np.ndarray):
        r["x"] = r["x"].tolist()
    return r


def read_results(path):
    """The rows of a results directory as a pyarrow Table, ordered by scenario index (an
    unreadable file is skipped with a warning; nothing in the folder is changed)."""
    rows = sorted(ResultStore(path, writer=False).load().values(), key=lambda r: r["index"])
    # (pyarrow: an optional extra, the batch one)
    import pyarrow as pa

    return pa.Table.from_pylist(rows, schema=_schema(rows))
