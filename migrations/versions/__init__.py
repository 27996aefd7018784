"""Alembic revisions, oldest first by their `0001_...` numbering."""
