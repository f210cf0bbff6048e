#!/usr/bin/env bash
# Throwaway PostgreSQL server for the storage/API tests.
#
#   .ci/postgres.sh start   install (Debian package, if missing), initdb, start on 127.0.0.1; prints
#                           BODYSCAN_TEST_POSTGRES_URL=postgresql+psycopg://...  (eval-able)
#   .ci/postgres.sh stop    stop the server and delete its data directory
#
# Environment: BODYSCAN_PG_DIR (default /tmp/bodyscan-pg), BODYSCAN_PG_PORT (default 54329).
# Runs as root (the server itself runs as the 'postgres' user) or as any user owning BODYSCAN_PG_DIR.
set -euo pipefail

DIR="${BODYSCAN_PG_DIR:-/tmp/bodyscan-pg}"
PORT="${BODYSCAN_PG_PORT:-54329}"
DB=bodyscan_test

log() { echo "postgres.sh: $*" >&2; }

find_bindir() {
    local d
    for d in /usr/lib/postgresql/*/bin; do
        [ -x "$d/initdb" ] && { echo "$d"; return 0; }
    done
    command -v initdb >/dev/null 2>&1 && { dirname "$(readlink -f "$(command -v initdb)")"; return 0; }
    return 1
}

install_pg() {
    if [ "$(id -u)" != 0 ]; then
        log "PostgreSQL is not installed and installing it needs root"; return 1
    fi
    log "installing the Debian postgresql package"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq >&2 && apt-get install -y -qq postgresql >&2
}

as_owner() {
    if [ "$(id -u)" = 0 ]; then runuser -u postgres -- "$@"; else "$@"; fi
}

start() {
    local bin
    bin="$(find_bindir)" || { install_pg && bin="$(find_bindir)"; } || { log "no PostgreSQL available"; exit 1; }
    if [ -f "$DIR/data/postmaster.pid" ] && as_owner "$bin/pg_ctl" -D "$DIR/data" status >/dev/null 2>&1; then
        log "already running in $DIR"
    else
        rm -rf "$DIR"
        mkdir -p "$DIR"
        [ "$(id -u)" = 0 ] && chown postgres: "$DIR"
        as_owner "$bin/initdb" -D "$DIR/data" -U postgres --auth=trust -E UTF8 --locale=C.UTF-8 >"$DIR/initdb.log" 2>&1 \
            || { cat "$DIR/initdb.log" >&2; exit 1; }
        as_owner "$bin/pg_ctl" -D "$DIR/data" -l "$DIR/server.log" -w -t 30 \
            -o "-p $PORT -k $DIR -c listen_addresses=127.0.0.1 -c fsync=off" start >&2 \
            || { cat "$DIR/server.log" >&2; exit 1; }
        as_owner "$bin/createdb" -h 127.0.0.1 -p "$PORT" -U postgres "$DB"
    fi
    echo "BODYSCAN_TEST_POSTGRES_URL=postgresql+psycopg://postgres@127.0.0.1:$PORT/$DB"
}

stop() {
    local bin
    bin="$(find_bindir)" || exit 0
    if [ -d "$DIR/data" ]; then
        as_owner "$bin/pg_ctl" -D "$DIR/data" -m fast -w stop >&2 || true
    fi
    rm -rf "$DIR"
}

case "${1:-start}" in
    start) start ;;
    stop) stop ;;
    *) echo "usage: $0 start|stop" >&2; exit 2 ;;
esac
