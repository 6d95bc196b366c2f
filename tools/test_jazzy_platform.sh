#!/usr/bin/env bash
# Run the test suite with the Python packages of ROS 2 Jazzy's platform (Ubuntu 24.04's
# numpy, numba, scipy, matplotlib, PyYAML: tools/jazzy_platform.txt) instead of the pins
# of requirements.txt:
#   tools/test_jazzy_platform.sh [PYTEST ARGS...]     (default: the whole suite, test/)
# Builds the venv on first use (like ./run.sh: requirements.txt with those packages
# replaced, the package as an editable install, tf2_msgs by tools/build_tf2_msgs.sh),
# in .venv-jazzy or $ROTATION_NODE_JAZZY_VENV. Its numba writes its compiled kernels to
# VENV/numba_cache, not next to the sources, where .venv's numba keeps its own.
set -euo pipefail
cd "$(dirname "$0")/.."
venv="${ROTATION_NODE_JAZZY_VENV:-$PWD/.venv-jazzy}"
python="${PYTHON:-python3}"
platform=tools/jazzy_platform.txt

want=$(cat requirements.txt "$platform" setup.py setup.cfg tools/build_tf2_msgs.sh \
  tools/tf2_msgs/requirements.txt | sha256sum | cut -d' ' -f1)
if [ ! -x "$venv/bin/python" ] || [ "$want" != "$(cat "$venv/.installed" 2>/dev/null)" ]; then
  echo "test_jazzy_platform.sh: setting up $venv" >&2
  "$python" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  # requirements.txt less the packages the platform provides, plus the platform's versions
  replaced=$(grep -v '^#' "$platform" | cut -d= -f1 | paste -sd'|')
  requirements="$venv/requirements-jazzy.txt"
  grep -v -i -E "^($replaced)[[:space:]]*[=<>~!]" requirements.txt > "$requirements"
  grep -v '^#' "$platform" >> "$requirements"
  "$venv/bin/python" -m pip install --quiet -r "$requirements"
  "$venv/bin/python" -m pip install --quiet --no-deps -e .
  tools/build_tf2_msgs.sh "$venv"
  echo "$want" > "$venv/.installed"
fi
export NUMBA_CACHE_DIR="$venv/numba_cache"
"$venv/bin/python" - "$platform" <<'PY'
import importlib.metadata, sys
pins = [line.split('==') for line in open(sys.argv[1]) if line.strip() and line[0] != '#']
have = {name: importlib.metadata.version(name) for name, _ in pins}
wrong = {name: have[name] for name, version in pins if have[name] != version.strip()}
if wrong:
    sys.exit(f'test_jazzy_platform.sh: error: the venv has {wrong}, not the platform versions')
print('test_jazzy_platform.sh: ' + ', '.join(f'{n} {v}' for n, v in have.items()), flush=True)
PY
"$venv/bin/python" -m rotation_node.conversions.warm_up
if [ "$#" -eq 0 ]; then
  set -- test
fi
exec "$venv/bin/python" -m pytest "$@"
