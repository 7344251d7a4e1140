"""Errors that chronocl raises on bad input.

Every error is a `ChronoclError` and also the builtin a Python caller would
expect (`ValueError`, `FileNotFoundError`, ...), so both ``except
ChronoclError`` and ``except ValueError`` work. The message is one line that
names the problem and, where there is one, the fix; the CLI prints it as is
and exits with code 2.
"""

from __future__ import annotations


class ChronoclError(Exception):
    """Base class of every error chronocl raises on purpose."""

    exit_code = 2


class InvalidDataError(ChronoclError, ValueError):
    """Input data are malformed: wrong size, non-finite values, bad shape."""


class InvalidSelectionError(ChronoclError, ValueError):
    """A time window, stride or step list that does not fit the series."""


class InvalidTransferFunctionError(ChronoclError, ValueError):
    """A transfer function that is malformed (NaN, unsorted, out of range, wrong length)."""


class UnknownNameError(ChronoclError, ValueError):
    """An unknown mode, order, preset, format or data set name."""


class InvalidParameterError(ChronoclError, ValueError):
    """Any other out-of-range or malformed parameter."""


class InputNotFoundError(ChronoclError, FileNotFoundError):
    """An input file, glob or store that does not exist."""


class OutputExistsError(ChronoclError, FileExistsError):
    """The output path exists and --overwrite was not given."""


class StoreFormatError(ChronoclError, ValueError):
    """A path that exists but is not a chronocl store or chronovolume."""


class EngineUnavailableError(ChronoclError, RuntimeError):
    """No OpenCL platform or device is available (or the named one does not exist)."""


class KernelBuildError(ChronoclError, RuntimeError):
    """An OpenCL program failed to build; the message carries options, device and log."""


class RendererUnavailableError(ChronoclError, RuntimeError):
    """No OpenGL context can be made (EGL or a GL driver is missing)."""


class StoreChangedError(ChronoclError, RuntimeError):
    """A store changed underneath an open series (steps added or removed)."""


class SupersededError(ChronoclError, RuntimeError):
    """A data request was cancelled because a newer request replaced it."""


class StoreCorruptError(ChronoclError, ValueError):
    """A store whose metadata disagree or whose chunks are missing or do not decode."""


class OutputNotWritableError(ChronoclError, PermissionError):
    """The output's folder cannot be written (permissions, read-only, a file used as a folder)."""


class OutputIsInputError(ChronoclError, ValueError):
    """The output is an input, lies inside one, or holds one: writing it would destroy input."""


class OutputBusyError(ChronoclError, FileExistsError):
    """Another live process is writing the same streamed output."""


class SlabTaskError(ChronoclError, RuntimeError):
    """A slab task was lost again and again (its workers died); a re-run resumes."""


class ModeDefinitionError(ChronoclError, TypeError):
    """A mode class promises a hook it lacks, or sets a flag out of its choices (raised where
    the class is defined, at import)."""


class ChronoclWarning(UserWarning):
    """Input that is probably not what was meant but may be (the work goes on); the CLI
    prints it as one line, 'chronocl: warning: ...'."""


class RemoteStoreError(ChronoclError, ConnectionError):
    """A remote store (HTTP, S3) that could not be read after the retries: the URL and the
    status are named; nothing is read as zeros."""


class RemoteAccessError(ChronoclError, PermissionError):
    """A remote store that refuses access (HTTP 401/403, S3 AccessDenied, wrong credentials)."""
