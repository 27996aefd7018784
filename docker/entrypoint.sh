#!/bin/sh
# Entrypoint of the fleetcal image: `api`, `worker` or `migrate`, then that role's own options.
# Settings come from FLEETCAL_* variables (database, storage, limits); see service/settings.py.
# Each role execs its process, so SIGTERM from `docker stop` reaches it directly: the API closes,
# a worker finishes or gives back its runs (within FLEETCAL_SHUTDOWN_GRACE seconds).
set -eu

role="${1:-api}"
[ "$#" -gt 0 ] && shift

case "$role" in
    api)
        # API only: the runs are calibrated by the `worker` containers.
        exec fleetcal serve --workers 0 \
            --host "${FLEETCAL_HOST:-0.0.0.0}" --port "${FLEETCAL_PORT:-8000}" \
            --shutdown-grace "${FLEETCAL_SHUTDOWN_GRACE:-30}" "$@"
        ;;
    worker)
        exec fleetcal worker \
            --concurrency "${FLEETCAL_WORKER_CONCURRENCY:-$(nproc)}" \
            --shutdown-grace "${FLEETCAL_SHUTDOWN_GRACE:-30}" "$@"
        ;;
    migrate)
        exec fleetcal db upgrade "$@"
        ;;
    *)
        # Anything else is a fleetcal command, e.g. `keys create --scope admin`.
        exec fleetcal "$role" "$@"
        ;;
esac
