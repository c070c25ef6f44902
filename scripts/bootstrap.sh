#!/usr/bin/env bash
# Create .venv with a Python >= 3.12 found on this machine and install fenics-contact into it (editable),
# with DOLFINx 0.11 from the binary wheel (the `wheel` extra) and the extras named in EXTRAS (default: test,docs).
# Usage: scripts/bootstrap.sh   (called by `make demo` / `make test` / `make docs` when .venv is missing or stale)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
EXTRAS=${EXTRAS:-test,docs}

is_ok() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; }

find_python() {
    local candidates=()
    [ -n "${PYTHON:-}" ] && candidates+=("$PYTHON")
    for name in python3.13 python3.12 python3 python; do
        command -v "$name" >/dev/null 2>&1 && candidates+=("$(command -v "$name")")
    done
    local roots=()
    command -v pyenv >/dev/null 2>&1 && roots+=("$(pyenv root)")
    roots+=("${PYENV_ROOT:-$HOME/.pyenv}")
    for root in "${roots[@]}"; do
        for p in $(ls -d "$root"/versions/3.1[2-9]*/bin/python3 2>/dev/null | sort -rV); do
            candidates+=("$p")
        done
    done
    for p in "${candidates[@]}"; do
        if is_ok "$p"; then echo "$p"; return 0; fi
    done
    return 1
}

if [ ! -x "$VENV/bin/python" ] || ! is_ok "$VENV/bin/python"; then
    if ! PY=$(find_python); then
        echo "fenics-contact needs Python >= 3.12 (the DOLFINx wheel requires it) and none was found." >&2
        echo "Install one (e.g. 'pyenv install 3.12' or your distribution's python3.12 package)," >&2
        echo "or point PYTHON=/path/to/python3.12 at it, then run the command again." >&2
        exit 1
    fi
    echo "creating $VENV with $PY ($("$PY" --version))"
    rm -rf "$VENV"
    "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install --quiet --upgrade pip
"$VENV/bin/python" -m pip install --quiet -e ".[wheel,$EXTRAS]"
"$VENV/bin/python" -c "import fenics_contact, dolfinx; print('fenics-contact', fenics_contact.__version__, 'with DOLFINx', dolfinx.__version__)"
touch "$VENV/.installed"
