"""The REST API: dependencies and one router per resource under ``/api/v1``."""
