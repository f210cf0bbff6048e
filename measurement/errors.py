"""Errors raised by the measurement core; the web layer maps them to 4xx responses in one place."""


class MeasurementError(Exception):
    """Base of every error the core raises on bad input or an impossible measurement."""


class ImageError(MeasurementError):
    """An image file is unreadable, truncated, of the wrong size or otherwise unusable."""


class CaptureError(MeasurementError):
    """A capture folder or archive does not follow the capture layout."""


class CalibrationError(MeasurementError):
    """Camera or light-plane calibration cannot be computed from the given images."""


class StripeDetectionError(MeasurementError):
    """No usable stripe pattern was found in an image."""


class ScanError(MeasurementError):
    """A scan image cannot be turned into a point cloud or measurements."""


def naming_files(exc: MeasurementError, image: str, ambient: str | None = None) -> MeasurementError:
    """The same error with the files named: the core's messages about a frame start with "image" or
    "ambient image"; those become the file names, any other message is prefixed with the image's."""
    text = str(exc)
    if ambient is not None and text.startswith("ambient image"):
        text = ambient + text[len("ambient image"):]
    elif text.startswith("image"):
        text = image + text[len("image"):]
    else:
        text = f"{image}: {text}"
    return type(exc)(text)
