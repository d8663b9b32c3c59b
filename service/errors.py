"""The one exception type for bad requests, and the HTTP status each kind of problem maps to.

Decoding and validation raise :class:`InputError` with a message that names the part and the problem; the
app turns it into ``{"detail": message}`` with the status it carries. It subclasses ValueError so that
offline callers (the pipeline, the evaluation) can catch it like any other bad-argument error.
"""

from __future__ import annotations

BAD_REQUEST = 400  # the body is not a well-formed multipart form
PAYLOAD_TOO_LARGE = 413  # a body or an image beyond the configured limits
UNSUPPORTED_MEDIA = 415  # not multipart/form-data, or an image that is neither PNG nor JPEG
# well-formed but wrong: bad JSON, missing image, 8-bit depth, size mismatch, non-rigid pose
UNPROCESSABLE = 422


class InputError(ValueError):
    """A request the service cannot process; ``status`` is the 4xx to answer with."""

    def __init__(self, message: str, status: int = UNPROCESSABLE) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
