"""The few exception types Albedit raises, each meaningful to a caller."""


class AlbeditError(Exception):
    """Base class of every error Albedit raises on purpose."""


class InputError(AlbeditError, ValueError):
    """An argument has the wrong shape, dtype, range or content.

    The message names the argument, shows the bad value or shape and says what was expected.
    """


class DeviceError(AlbeditError, RuntimeError):
    """A camera or projector failed, timed out, or is not there."""


class SessionError(AlbeditError, RuntimeError):
    """A session folder is missing, corrupt, of an unknown version or unsafe to load."""


class Cancelled(AlbeditError):
    """Long work was stopped on request; everything finished before the stop is kept."""


class DiskFull(SessionError):
    """A session write failed because its disk is full; everything written before is kept.

    Attributes
    ----------
    free : int
        Bytes free on the session's disk when the write failed.
    needed : int
        Bytes the failed write needed (an estimate: more is needed for what is still to come).
    """

    def __init__(self, message: str, *, free: int, needed: int) -> None:
        super().__init__(message)
        self.free = free
        self.needed = needed
