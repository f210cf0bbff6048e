"""Errors raised by the storage layer; app/errors.py maps them to HTTP responses in one place."""


class StorageError(Exception):
    """Base of the storage errors."""


class NotFoundError(StorageError):
    """A record with the given id does not exist (404)."""

    def __init__(self, what: str, ident: object) -> None:
        super().__init__(f"{what} {ident} not found")
        self.what = what
        self.ident = ident


class ConflictError(StorageError):
    """The request contradicts stored state, e.g. a duplicate tag or an unfinished calibration (409)."""


class InvalidInputError(StorageError):
    """A value is well-formed but unusable, e.g. a picked point far from the scan surface (422)."""
