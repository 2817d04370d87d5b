"""Entry points: an expected error (unreadable or malformed input, a missing file, an invalid setting) reaches
the user as one line on stderr and exit status 2; anything else keeps its traceback. ``IRMCL_TRACEBACK=1``
shows the traceback of expected errors too.

Every ``python -m ...`` entry calls its stage through ``run_entry`` (Hydra entries) or wraps its ``main`` in
``guard`` (argparse entries).
"""

from __future__ import annotations

import errno
import os
import sys

from irmcl_warp.config import ConfigError, settings_warnings, validate
from irmcl_warp.io.atomic import DiskFullError
from irmcl_warp.io.errors import LogFormatError

# what a user's input or settings cause; a bug surfaces as another type and keeps its traceback
EXPECTED = (LogFormatError, ConfigError, DiskFullError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError,
            ValueError)


def _fail(e: BaseException) -> None:
    if os.environ.get("IRMCL_TRACEBACK") == "1":
        raise e
    text = e.strerror if isinstance(e, DiskFullError) else str(e)
    message = " ".join(str(text).split("\n")[:1]) or type(e).__name__
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def _full_disk(e: OSError) -> bool:
    return e.errno in (errno.ENOSPC, errno.EDQUOT)


def run_entry(run, cfg):
    """``run(cfg)`` after the settings are checked; an expected error becomes one line and exit status 2."""
    try:
        validate(cfg)
        for line in settings_warnings(cfg):
            print(f"warning: {line}", file=sys.stderr)
        return run(cfg)
    except EXPECTED as e:
        _fail(e)
    except OSError as e:
        if not _full_disk(e):
            raise
        _fail(DiskFullError(e.errno, f"no space left on the device ({e.filename or 'while writing'})"))


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
