"""The application: MQTT ingest, storage, online runner, REST API."""
