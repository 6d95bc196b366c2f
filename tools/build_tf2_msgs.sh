#!/usr/bin/env bash
# Build and install tf2_msgs (tf2_msgs/msg/TFMessage) into a Python venv whose ROS 2
# packages come from PyPI, where tf2_msgs is not published:
#   tools/build_tf2_msgs.sh VENV
# Does nothing when `import tf2_msgs.msg` already works in VENV (with a ROS install,
# tf2_msgs is the distribution's package). Needs cmake and a C/C++ compiler; ~1 min.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
venv=$(cd "${1:?usage: tools/build_tf2_msgs.sh VENV}" && pwd)
python="$venv/bin/python"

if "$python" -c 'import tf2_msgs.msg' 2>/dev/null; then
  exit 0
fi
for tool in cmake make cc c++; do
  command -v "$tool" >/dev/null || {
    echo "build_tf2_msgs.sh: error: $tool not found (building tf2_msgs needs cmake, make and a C/C++ compiler)" >&2
    exit 1
  }
done
echo "build_tf2_msgs.sh: building tf2_msgs into $venv" >&2
"$python" -m pip install --quiet -r "$here/tf2_msgs/requirements.txt"

# The wheels' CMake exports of the Python type support name the include
# directories of the machine they were built on; point them at this venv's.
python_include=$("$python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
numpy_include=$("$python" -c 'import numpy; print(numpy.get_include())')
exports=("$venv"/share/*/cmake/export_*__rosidl_generator_pyExport.cmake)
sed -i -E \
  -e "s#/opt/python/[^/;\"]+/include/python[0-9.]+#${python_include}#g" \
  -e "s#/opt/python/[^;\"]+/site-packages/numpy/_core/include#${numpy_include}#g" \
  "${exports[@]}"
if grep -l '/opt/python/' "${exports[@]}" >&2; then
  echo "build_tf2_msgs.sh: error: the files above still name /opt/python/ include paths" >&2
  exit 1
fi

build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
export AMENT_PREFIX_PATH="$venv" CMAKE_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH"
cmake -S "$here/tf2_msgs" -B "$build" -DCMAKE_INSTALL_PREFIX="$venv" \
  -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
  -DPython3_EXECUTABLE="$python" -DPython3_FIND_VIRTUALENV=ONLY >"$build/cmake.log" 2>&1 \
  && cmake --build "$build" -j "$(nproc)" >>"$build/cmake.log" 2>&1 \
  && cmake --install "$build" >>"$build/cmake.log" 2>&1 \
  || { tail -n 40 "$build/cmake.log" >&2; echo "build_tf2_msgs.sh: error: tf2_msgs build failed" >&2; exit 1; }

"$python" -c 'from tf2_msgs.msg import TFMessage' || {
  echo "build_tf2_msgs.sh: error: tf2_msgs was built but does not import" >&2
  exit 1
}
