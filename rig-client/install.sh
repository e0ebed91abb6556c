#!/usr/bin/env bash
# Install rig-client (the rig's C/C++ client library, issue 27) into a prefix:
#   rig-client/install.sh --prefix /usr/local
# builds it (cargo build --release -p rig-client) and installs
#   PREFIX/lib/librig_client.so, PREFIX/lib/librig_client.a
#   PREFIX/include/rig_client.h, PREFIX/include/rig_client.hpp
#   PREFIX/lib/cmake/RigClient/RigClientConfig.cmake   (find_package(RigClient))
#   PREFIX/lib/pkgconfig/rig_client.pc                 (pkg-config --cflags --libs rig_client)
set -euo pipefail
prefix=""
while [ $# -gt 0 ]; do
  case "$1" in
    --prefix) prefix="$2"; shift 2 ;;
    --prefix=*) prefix="${1#--prefix=}"; shift ;;
    *) echo "usage: $0 --prefix DIR" >&2; exit 2 ;;
  esac
done
[ -n "$prefix" ] || { echo "usage: $0 --prefix DIR" >&2; exit 2; }
here="$(cd "$(dirname "$0")" && pwd)"
cd "$here/.."
cargo build --release -p rig-client
target="${CARGO_TARGET_DIR:-$PWD/target}/release"
mkdir -p "$prefix"
prefix="$(cd "$prefix" && pwd)"
version="$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n1)"
install -d "$prefix/lib" "$prefix/include" "$prefix/lib/cmake/RigClient" "$prefix/lib/pkgconfig"
install -m 0755 "$target/librig_client.so" "$prefix/lib/"
install -m 0644 "$target/librig_client.a" "$prefix/lib/"
install -m 0644 "$here/include/rig_client.h" "$here/include/rig_client.hpp" "$prefix/include/"
sed "s/@VERSION@/$version/" "$here/cmake/RigClientConfig.cmake" > "$prefix/lib/cmake/RigClient/RigClientConfig.cmake"
cat > "$prefix/lib/pkgconfig/rig_client.pc" <<PC
prefix=$prefix
libdir=\${prefix}/lib
includedir=\${prefix}/include

Name: rig_client
Description: C client library of the rig (plant-sim over iceoryx2): contract records, ports, robot model
Version: $version
Libs: -L\${libdir} -Wl,-rpath,\${libdir} -lrig_client
Libs.private: -lpthread -ldl -lm -lrt
Cflags: -I\${includedir}
PC
echo "rig-client $version installed in $prefix (find_package(RigClient) with CMAKE_PREFIX_PATH=$prefix; pkg-config: PKG_CONFIG_PATH=$prefix/lib/pkgconfig)"
