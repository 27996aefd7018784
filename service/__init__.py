"""fleetcal's service: the FastAPI app (`service.app.create_app`), its database, storage, API keys
and settings. Depends on `pipeline` only through its public API; never imported by `pipeline`."""
