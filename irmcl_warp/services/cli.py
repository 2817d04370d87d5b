"""Entry points: an expected error (unreadable or malformed input, a missing file, an invalid setting) reaches
the user as one line on stderr and exit status 2; anything else keeps its traceback. ``IRMCL_TRACEBACK=1``
shows the traceback of expected errors too.

Every ``python -m ...`` entry calls its stage through ``run_entry`` (Hydra entries, started by ``hydra_main``) or
wraps its ``main`` in ``guard`` (argparse entries).
"""

from __future__ import annotations

import errno
import logging
import os
import sys

from irmcl_warp.config import ConfigError, settings_warnings, validate
from irmcl_warp.extend import load_plugins
from irmcl_warp.io.atomic import DiskFullError
from irmcl_warp.io.errors import LogFormatError

# what a user's input or settings cause; a bug surfaces as another type and keeps its traceback
EXPECTED = (
    LogFormatError,
    ConfigError,
    DiskFullError,
    FileNotFoundError,
    IsADirectoryError,
    NotADirectoryError,
    PermissionError,
    ValueError,
)


def _fail(e: BaseException) -> None:
    if os.environ.get("IRMCL_TRACEBACK") == "1":
        raise e
    text = e.strerror if isinstance(e, DiskFullError) else str(e)
    message = " ".join(str(text).split("\n")[:1]) or type(e).__name__
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def _full_disk(e: OSError) -> bool:
    return e.errno in (errno.ENOSPC, errno.EDQUOT)


_STARTED = []  # set once Hydra composed a config and handed it to run_entry


def hydra_main(main) -> None:
    """A Hydra entry's ``main()``: Hydra's own mistakes (an unknown key, a missing ``+exp``, a bad override) exit
    with status 2 like ours, where Hydra says 1; a run that started keeps its status (1: a bug's traceback). A
    sweep (``-m``) keeps Hydra's status: its jobs run in other processes, so a failed job cannot be told from a
    mistake here."""
    try:
        main()
    except SystemExit as e:
        if e.code == 1 and not _STARTED and not {"-m", "--multirun"} & set(sys.argv[1:]):
            sys.exit(2)
        raise


class _IntoLogFiles:
    """A console stream that also hands each complete line to the log files Hydra opened (its ``<job>.log``),
    so the file holds what the run said; the console handlers are left out (the line is on the console already)."""

    def __init__(self, stream, handlers, level):
        self.stream, self.handlers, self.level, self.pending = stream, handlers, level, ""

    def write(self, text):
        n = self.stream.write(text)
        self.pending += text
        *lines, self.pending = self.pending.split("\n")
        for line in filter(None, (part.rsplit("\r", 1)[-1] for part in lines)):  # a progress bar: its last state
            record = logging.LogRecord("irmcl_warp", self.level, __file__, 0, line, None, None)
            for h in self.handlers:
                h.handle(record)
        return n

    def __getattr__(self, name):
        return getattr(self.stream, name)


def registered_choices() -> dict:
    """The choices the registries hold (built-in and plugins'), for the settings a registry implements."""
    from irmcl_warp.kernels import WEIGHTING
    from irmcl_warp.slam.rbpf import PROPOSALS

    return {"mcl.weighting": WEIGHTING.names(), "slam.proposal": PROPOSALS.names()}


def run_entry(run, cfg):
    """``run(cfg)`` after the settings are checked; an expected error becomes one line and exit status 2. What
    the run prints also goes to Hydra's log file (``outputs/<exp>/<job>.log``), warnings and errors as such."""
    _STARTED.append(True)
    files = [h for h in logging.getLogger().handlers if isinstance(h, logging.FileHandler)]
    out, err = sys.stdout, sys.stderr
    if files:
        sys.stdout, sys.stderr = _IntoLogFiles(out, files, logging.INFO), _IntoLogFiles(err, files, logging.WARNING)
    try:
        load_plugins(cfg.get("plugins"))
        validate(cfg, registered_choices())
        for line in settings_warnings(cfg):
            print(f"warning: {line}", file=sys.stderr)
        return run(cfg)
    except EXPECTED as e:
        _fail(e)
    except OSError as e:
        if not _full_disk(e):
            raise
        _fail(DiskFullError(e.errno, f"no space left on the device ({e.filename or 'while writing'})"))
    finally:
        sys.stdout, sys.stderr = out, err


def guard(main, argv=None):
    """``main(argv)`` of an argparse entry point, expected errors as one line and exit status 2."""
    try:
        return main(argv)
    except EXPECTED as e:
        _fail(e)
    except OSError as e:
        if not _full_disk(e):
            raise
        _fail(DiskFullError(e.errno, f"no space left on the device ({e.filename or 'while writing'})"))
