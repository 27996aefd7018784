"""Alembic migrations of the service database (configured from `service.db.alembic_config`)."""
