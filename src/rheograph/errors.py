"""The one error type for bad user input (and its one special case, ``OtherRunError``): a parameter out
of range, a file that is not what it should be, a glob that matches nothing.  Its message names the key,
value or file and what to do; entry points print it as one line and exit non-zero (``one_line_errors``)."""

import errno
import os
import sys
from contextlib import contextmanager

NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)  # disk full, quota reached, file-size limit


def hdf5_write_found_no_room(exc: OSError) -> bool:
    """Whether an OSError raised while writing an HDF5 file is a write that found no room: h5py's write
    errors carry no errno (their message is HDF5's), the operating system's say ENOSPC / EDQUOT / EFBIG;
    any other errno (a closed pipe, a missing file) is something else."""
    return exc.errno is None or exc.errno in NO_ROOM


class InputError(ValueError):
    """Bad input from the user (configuration, command line or file)."""


class OtherRunError(InputError):
    """A training run directory that holds folds of another configuration or of other data: resuming
    into it would mix them."""


def _no_room_message(exc: OSError) -> str:
    where = f" {exc.filename}" if exc.filename else ""
    return (
        f"no room to write{where} ({exc.strerror}): is the disk full or a quota reached? Free space and "
        "rerun the same command (with the same output directory) to resume"
    )


@contextmanager
def one_line_errors(program: str):
    """Bad input (``InputError``, also when Hydra's instantiate wraps it) and a write that found no room
    (disk full, quota: ``NO_ROOM``) end the program with one line naming the problem and a non-zero
    status; ``HYDRA_FULL_ERROR=1`` or ``RHEOGRAPH_DEBUG=1`` re-raises it with its traceback."""
    try:
        yield
    except Exception as exc:
        cause = exc
        while cause is not None and not (
            isinstance(cause, InputError) or (isinstance(cause, OSError) and cause.errno in NO_ROOM)
        ):
            cause = cause.__cause__
        if cause is None or os.environ.get("HYDRA_FULL_ERROR") == "1" or os.environ.get("RHEOGRAPH_DEBUG"):
            raise
        sys.exit(f"{program}: error: {cause if isinstance(cause, InputError) else _no_room_message(cause)}")
