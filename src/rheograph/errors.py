"""The one error type for bad user input (and its one special case, ``OtherRunError``): a parameter out
of range, a file that is not what it should be, a glob that matches nothing.  Its message names the key,
value or file and what to do; entry points print it as one line and exit non-zero (``one_line_errors``)."""

import errno
import logging
import multiprocessing
import os
import re
import sys
from contextlib import contextmanager
from pathlib import Path

NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)  # disk full, quota reached, file-size limit


def hdf5_write_found_no_room(exc: OSError) -> bool:
    """Whether an OSError raised while writing an HDF5 file is a write that found no room: h5py's write
    errors carry no errno (their message is HDF5's), the operating system's say ENOSPC / EDQUOT / EFBIG;
    any other errno (a closed pipe, a missing file) is something else."""
    return exc.errno is None or exc.errno in NO_ROOM


class InputError(ValueError):
    """Bad input from the user (configuration, command line or file)."""


class ParameterError(InputError):
    """A simulation parameter is outside its allowed range."""


class StatePointError(InputError):
    """A state point that cannot be run as asked, for a reason of its own physics (no overlap-free
    initial configuration at its area fraction): alone it ends the program like any bad input; in a
    sweep the other state points still run and the failed ones are listed at the end."""


class NoRoomError(InputError):
    """An HDF5 file whose writes found no room (disk full, quota, file-size limit), reported with what a
    rerun resumes from; the library may still hold the file open."""


class OtherRunError(InputError):
    """A training run directory that holds folds of another configuration or of other data: resuming
    into it would mix them."""


class RefusedBeforeRun(BaseException):
    """Carries an ``InputError`` raised before Hydra makes the run directory (in a Hydra callback, whose
    ``Exception``s Hydra only turns into warnings) out to ``run_hydra_app``, which ends the program with
    it as one line."""

    def __init__(self, error: InputError):
        super().__init__(str(error))
        self.error = error


def _no_room_message(exc: OSError) -> str:
    where = f" {exc.filename}" if exc.filename else ""
    return (
        f"no room to write{where} ({exc.strerror}): is the disk full or a quota reached? Free space and "
        "rerun the same command (with the same output directory) to resume"
    )


# h5py's report of an object it cannot release from a file whose writes failed (from its deallocator)
_RELEASE_FAILURE = "Can't decrement id ref count (file write failed"


@contextmanager
def _without_release_failure_reports():
    """Drops h5py's tracebacks for objects it cannot release from a file whose writes failed — one per
    open dataset, printed before the line that says what failed and what to do — and nothing else."""
    unraisablehook, excepthook = sys.unraisablehook, sys.excepthook

    def on_unraisable(info):
        if not str(info.exc_value).startswith(_RELEASE_FAILURE):
            unraisablehook(info)

    def on_exception(kind, value, traceback):
        if not str(value).startswith(_RELEASE_FAILURE):
            excepthook(kind, value, traceback)

    sys.unraisablehook, sys.excepthook = on_unraisable, on_exception
    try:
        yield
    finally:
        sys.unraisablehook, sys.excepthook = unraisablehook, excepthook


def wants_traceback() -> bool:
    """Whether the user asked for tracebacks instead of one-line errors: ``RHEOGRAPH_DEBUG`` set (and not
    0), or else ``HYDRA_FULL_ERROR=1`` (``run_hydra_app`` turns the latter into the former, since it sets
    ``HYDRA_FULL_ERROR`` itself)."""
    debug = os.environ.get("RHEOGRAPH_DEBUG")
    if debug is not None:
        return debug not in ("", "0")
    return os.environ.get("HYDRA_FULL_ERROR") == "1"


# config groups that only one entry point composes: (what they hold, who runs them, what the other takes)
GROUP_OWNERS = {
    "experiment": ("training experiments", "train.py", "campaign=<name> (conf/campaign/) for simulations"),
    "campaign": ("simulation campaigns", "simulate.py", "experiment=<name> (conf/experiment/) for training"),
}


def hydra_error_line(exc: Exception) -> str:
    """One line for what Hydra or OmegaConf refused while composing a configuration from the command line:
    an unknown key (with the closest known ones), an unknown config option (with the options), or the
    exception's own message with its lines joined."""
    import difflib

    from hydra.errors import MissingConfigException

    if isinstance(exc, MissingConfigException) and exc.options:
        first = str(exc).strip().splitlines()[0]
        return f"{first}; the options are: {', '.join(exc.options)}"
    key_error = exc.__cause__ if getattr(exc.__cause__, "full_key", None) else exc
    full_key, key = getattr(key_error, "full_key", None), getattr(key_error, "key", None)
    if full_key and "not in struct" in str(key_error):
        parent = getattr(key_error, "parent_node", None)
        known = [str(k) for k in parent.keys()] if hasattr(parent, "keys") else []
        close = difflib.get_close_matches(str(key), known, n=3)
        prefix = full_key[: -len(str(key))]
        hint = f"did you mean {' or '.join(prefix + c for c in close)}? " if close else ""
        return f"{full_key}: no such setting; {hint}`--cfg job` prints every setting of a command"
    wrong_group = re.match(r"Could not override '(experiment|campaign)'\. No match in the defaults", str(exc))
    if wrong_group:  # Hydra's advice (append with +) would compose a simulation with a training config
        group = wrong_group.group(1)
        return (
            f"{group}=...: {GROUP_OWNERS[group][0]} belong to {GROUP_OWNERS[group][1]}; this command "
            f"takes {GROUP_OWNERS[group][2]}"
        )
    lines = [line.strip().rstrip(".") for line in str(exc).splitlines() if line.strip()]
    override = getattr(exc, "override", None)  # a malformed override: the parser's message does not name it
    return (f"{override}: " if override else "") + ("; ".join(lines) or type(exc).__name__)


def _raised_in_hydra(exc: BaseException) -> bool:
    """Whether ``exc`` was raised by Hydra's own code (its last traceback frame lies in the package)."""
    import hydra

    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    package = Path(hydra.__file__).resolve().parent
    return tb is not None and package in Path(tb.tb_frame.f_code.co_filename).resolve().parents


def refuse_unpickling_flags(program: str, argv: list[str]) -> None:
    """Hydra's ``--experimental-rerun FILE`` (also abbreviated, as argparse allows: ``--exp``) unpickles
    FILE, and so runs whatever code the file holds; no entry point of this package reads a pickle, so it
    is refused in one line before Hydra sees it."""
    for arg in argv:
        flag = arg.split("=", 1)[0]
        if len(flag) >= 3 and "--experimental-rerun".startswith(flag):
            sys.exit(
                f"{program}: error: {flag}: not accepted (Hydra's rerun unpickles the file it is given, "
                "which could run any code); rerun with the same overrides instead (a run directory lists "
                "them in .hydra/overrides.yaml)"
            )


def _file_system_error(exc: BaseException) -> OSError | None:
    """The OSError naming a file behind ``exc`` (itself, or its cause: the logging module reports a log
    file it cannot open as a ValueError caused by it), or None."""
    while exc is not None:
        if isinstance(exc, OSError) and exc.filename is not None:
            return exc
        exc = exc.__cause__
    return None


def _run_directory_message(exc: OSError) -> str:
    if exc.errno in NO_ROOM:
        return _no_room_message(exc)
    return (
        f"cannot write {exc.filename} ({exc.strerror}): choose a writable output folder with "
        "output_root=<dir> (or hydra.run.dir=<dir>)"
    )


def run_hydra_app(app, program: str):
    """Runs a ``@hydra.main`` function: what Hydra refuses while composing the configuration from the
    command line (a misspelled key, an unknown config option, a malformed override) ends the program with
    one line naming it, like any bad input (Hydra itself prints several lines and a suggestion to add the
    key with ``+``, which would only hide the misspelling).  So do settings refused before the run
    directory is made (``RefusedBeforeRun``) and a run directory or log file that cannot be made or
    written (an OSError naming the file, outside the task)."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    refuse_unpickling_flags(program, sys.argv[1:])
    saved = {key: os.environ.get(key) for key in ("RHEOGRAPH_DEBUG", "HYDRA_FULL_ERROR")}
    os.environ["RHEOGRAPH_DEBUG"] = "1" if wants_traceback() else "0"
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises what it refuses instead of printing it
    try:
        return app()
    except RefusedBeforeRun as refused:
        if wants_traceback():
            raise refused.error from None
        sys.exit(f"{program}: error: {refused.error}")
    except (HydraException, OmegaConfBaseException, ValueError, OSError) as exc:
        # an error from inside the task (one_line_errors marks it) is not the command line's: it keeps
        # its traceback, as a bug should; of ValueErrors only Hydra's own (conflicting flags) are
        if wants_traceback() or getattr(exc, "raised_in_task", False):
            raise
        if isinstance(exc, (HydraException, OmegaConfBaseException)):  # (a missing config is an OSError)
            sys.exit(f"{program}: error: {hydra_error_line(exc)}")
        file_error = _file_system_error(exc)
        if file_error is not None:  # the run directory or its log could not be created or written
            sys.exit(f"{program}: error: {_run_directory_message(file_error)}")
        if isinstance(exc, OSError) or not _raised_in_hydra(exc):
            raise
        sys.exit(f"{program}: error: {hydra_error_line(exc)}")
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@contextmanager
def one_line_errors(program: str):
    """Bad input (``InputError``, also when Hydra's instantiate wraps it) and a write that found no room
    (disk full, quota: ``NO_ROOM``; ``NoRoomError`` for a trajectory) end the program with one line
    naming the problem and a non-zero status; ``RHEOGRAPH_DEBUG=1`` or ``HYDRA_FULL_ERROR=1`` re-raises it
    with its traceback (``wants_traceback``)."""
    try:
        with _without_release_failure_reports():
            yield
    except Exception as exc:
        cause = exc
        while cause is not None and not (
            isinstance(cause, InputError) or (isinstance(cause, OSError) and cause.errno in NO_ROOM)
        ):
            cause = cause.__cause__
        if cause is None or wants_traceback():
            exc.raised_in_task = True  # for run_hydra_app: not a composition error of the command line
            raise
        message = f"{program}: error: {cause if isinstance(cause, InputError) else _no_room_message(cause)}"
        in_main_process = multiprocessing.current_process().name == "MainProcess"
        if isinstance(cause, NoRoomError) and in_main_process:
            # the HDF5 library, at interpreter exit, flushes the trajectory whose writes failed once
            # more and can crash doing so (SIGSEGV, measured under a file-size limit): the error stays
            # the last word
            print(message, file=sys.stderr, flush=True)
            logging.shutdown()
            sys.stdout.flush()
            os._exit(1)
        sys.exit(message)
