"""One exception hierarchy for the whole library.

Messages name the file, the field, the problem and the expected form, so a user can fix their
input without reading our code.
"""

from __future__ import annotations

from pathlib import Path


class WearposeError(Exception):
    """Root of every error wearpose raises on purpose."""


class InputFileError(WearposeError, ValueError):
    """A file a user gave us is missing, unreadable or malformed.

    Args:
        path: the file.
        problem: what is wrong.
        expected: the form we expected (what a correct file looks like).
        field: the field/key/line inside the file, if the problem is local to one.
    """

    def __init__(self, path: str | Path, problem: str, expected: str, field: str | None = None):
        self.path = Path(path)
        self.problem = problem
        self.expected = expected
        self.field = field
        where = f"{self.path}" + (f" [{field}]" if field else "")
        super().__init__(f"{where}: {problem}. Expected: {expected}.")


class ShapeError(WearposeError, ValueError):
    """A tensor/array argument has the wrong shape, dtype or value range."""


class RecordingInputError(ShapeError):
    """A recording does not carry what an estimator reads (a sensor, a channel, a kind, a rate).

    Args:
        recording: how the recording is named: its file, or a note that it was made in memory.
        problem: what is wrong, naming the sensor and the field.
        expected: the form the estimator reads.
    """

    def __init__(self, recording: str, problem: str, expected: str):
        self.recording, self.problem, self.expected = recording, problem, expected
        super().__init__(f"{recording}: {problem}. Expected: {expected}")


class ConfigError(WearposeError, ValueError):
    """A configuration value or environment variable is invalid or missing."""
