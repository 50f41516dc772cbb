#!/usr/bin/env bash
# Install the ROS 2 Jazzy runtime wheels, the pinned build wheels, and build + install the
# printeps_interfaces package into the current (or given) Python environment.
# Usage: ros/install.sh [python]   (default: $VIRTUAL_ENV/bin/python, else python3)
# Needs cmake and a C/C++ compiler (apt: cmake g++). Idempotent: skips the build when installed.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
PY="${1:-${VIRTUAL_ENV:+$VIRTUAL_ENV/bin/python}}"
PY="${PY:-python3}"
for tool in cmake g++; do
  command -v "$tool" >/dev/null || { echo "ros/install.sh: '$tool' not found (apt-get install cmake g++)" >&2; exit 1; }
done
"$PY" -m pip install -q -r "$HERE/requirements-jazzy.txt"
# Rebuild when the .msg/.srv files changed since the installed build (their hash is kept beside it).
SRC_HASH="$(cat "$HERE"/printeps_interfaces/msg/*.msg "$HERE"/printeps_interfaces/srv/*.srv | sha256sum | cut -c1-16)"
HASH_FILE="$("$PY" -c 'import sys; print(sys.prefix)')/.printeps_interfaces.hash"
if "$PY" -c "import printeps_interfaces.msg, printeps_interfaces.srv" 2>/dev/null \
   && [ "$(cat "$HASH_FILE" 2>/dev/null)" = "$SRC_HASH" ] && [ "${PRINTEPS_ROS_REBUILD:-0}" != "1" ]; then
  echo "printeps_interfaces already installed (PRINTEPS_ROS_REBUILD=1 to rebuild)"
else
  "$PY" -m pip install -q --no-build-isolation --force-reinstall --no-deps "$HERE/printeps_interfaces"
  echo "$SRC_HASH" > "$HASH_FILE"
fi
"$PY" -c "from printeps_interfaces.msg import Entrance; from printeps_interfaces.srv import Speak; print('printeps_interfaces OK')"
