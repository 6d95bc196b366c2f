#!/usr/bin/env bash
# The two commands of the README:
#   ./run.sh main [ARGS...]   create .venv if missing, run the built-in demo job
#   ./run.sh test [ARGS...]   create .venv if missing, run the whole test suite in parallel
# Everything is installed from PyPI into .venv (override with ROTATION_NODE_VENV);
# tf2_msgs, which is not on PyPI, is built into it by tools/build_tf2_msgs.sh.
set -euo pipefail
cd "$(dirname "$0")"
venv="${ROTATION_NODE_VENV:-$PWD/.venv}"

ensure_env() {
  local want have
  want=$(cat requirements.txt setup.py setup.cfg tools/build_tf2_msgs.sh \
    tools/tf2_msgs/requirements.txt tools/tf2_msgs/CMakeLists.txt tools/tf2_msgs/package.xml \
    tools/tf2_msgs/msg/*.msg | sha256sum | cut -d' ' -f1)
  have=$(cat "$venv/.installed" 2>/dev/null || true)
  if [ -x "$venv/bin/python" ] && [ "$want" = "$have" ]; then
    return
  fi
  echo "run.sh: setting up $venv (first run only)" >&2
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  "$venv/bin/python" -m pip install --quiet -r requirements.txt
  "$venv/bin/python" -m pip install --quiet --no-deps -e .
  tools/build_tf2_msgs.sh "$venv"
  "$venv/bin/python" -m rotation_node.conversions.warm_up   # compile and cache every kernel once
  echo "$want" > "$venv/.installed"
}

cmd="${1:-}"
shift || true
case "$cmd" in
  main)
    ensure_env
    exec "$venv/bin/python" -m rotation_dev.demo "$@"
    ;;
  test)
    ensure_env
    # Parallel workers (pytest-xdist), one more than the cores (the slow tests spend most
    # of their time waiting for processes, discovery and signals: the extra worker computes
    # meanwhile), each in its own ROS domain; each test module runs on one worker (its
    # module-scoped fixtures made once), the modules with slow tests first (test/conftest.py).
    # The user's own -n (-n 0: serial) comes later and wins. No path: pytest runs
    # setup.cfg's testpaths (test/), or the files given.
    exec "$venv/bin/python" -m pytest -n "$(($(nproc) + 1))" --dist loadscope \
      --no-loadscope-reorder "$@"
    ;;
  *)
    echo "usage: ./run.sh main [ARGS...] | ./run.sh test [PYTEST ARGS...]" >&2
    exit 2
    ;;
esac
