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
