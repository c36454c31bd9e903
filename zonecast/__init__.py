"""zonecast: bilinear RC building models identified from telemetry."""
__version__ = "0.1.0"
