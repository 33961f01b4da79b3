#!/usr/bin/env bash
# `make dreal`: the paper's solver for real. dReal's wheel on PyPI (dreal==4.21.6.2) links against libibex, which
# no package index has; this builds IBEX 2.7.4 (dReal's fork) from a source tarball into a cache directory that
# survives `make clean`, installs the pinned wheel into the venv, and writes the file synth/smt/dreal_backend.py
# reads to load libibex by absolute path (so nobody sets LD_LIBRARY_PATH). A second run takes a second or two.
#
# Environment: IBEX_SRC (the tarball; needed unless its build is in the cache already), VENV (default .venv),
# PYTHON (builds with it; default python3.11), IBEX_SHA256 (the tarball's expected sha256; default: that of
# ibex-lib-2.7.4_11.tar.gz), DREAL_CACHE (default ${XDG_CACHE_HOME:-~/.cache}/r2sgen), JOBS (default 2).
set -euo pipefail

# The Debian packages dReal needs, named once: bison, flex, g++, pkg-config and coinor-libclp-dev build IBEX;
# libclp1 (via -dev), libnlopt0, liblapack3, libblas3, libbz2-1.0 and zlib1g are what the wheel links against.
APT_PACKAGES="bison flex g++ pkg-config coinor-libclp-dev libnlopt0 liblapack3 libblas3 libbz2-1.0 zlib1g"
IBEX_VERSION=2.7.4_11
RECIPE=2   # how IBEX is configured here: a prefix built by another recipe is rebuilt
DEFAULT_SHA256=938d6090ee2265bdd55e99d35a033f90c6e9b0723d6c53050fbe3e6079cfeb9b
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3.11}

die() { echo "make dreal: $*" >&2; exit 2; }

test -x "$VENV/bin/python" || die "no venv at $VENV (run make setup first)"
expected=${IBEX_SHA256:-$DEFAULT_SHA256}
if [ -n "${IBEX_SRC:-}" ]; then
    test -f "$IBEX_SRC" || die "IBEX_SRC=$IBEX_SRC is not a file"
    IBEX_SRC=$(realpath "$IBEX_SRC")
    sha=$(sha256sum "$IBEX_SRC" | cut -d' ' -f1)
    test "$sha" = "$expected" \
        || die "$IBEX_SRC has sha256 $sha, expected $expected (set IBEX_SHA256 to accept another build of ibex-$IBEX_VERSION)"
else
    sha=$expected   # no source at hand: a prefix built from it before still serves
fi

cache=${DREAL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/r2sgen}
prefix=$cache/ibex-$IBEX_VERSION-${sha:0:16}   # keyed by the source: another tarball, another prefix
lib=$prefix/lib/libibex.so
built() { test -f "$lib" -a "$(cat "$prefix/.complete" 2>/dev/null)" = "$RECIPE"; }
built || test -n "${IBEX_SRC:-}" \
    || die "no IBEX source: set IBEX_SRC=PATH/ibex-lib-$IBEX_VERSION.tar.gz (dreal-deps/ibex-lib, tag ibex-$IBEX_VERSION)"

missing_packages() {
    local p out=""
    for p in $APT_PACKAGES; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'ok installed' || out="$out $p"
    done
    echo "${out# }"
}

install_packages() {
    command -v dpkg-query >/dev/null || { echo "make dreal: not Debian/Ubuntu; install the equivalents of: $APT_PACKAGES" >&2; return; }
    local missing
    missing=$(missing_packages)
    test -z "$missing" && return
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "make dreal: installing Debian packages: $missing"
        { DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $missing \
            || { apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $missing; }
        } >"$cache/apt.log" 2>&1 || { tail -20 "$cache/apt.log" >&2; die "apt-get could not install: $missing"; }
    else
        die "missing Debian packages; run: sudo apt-get install $missing"
    fi
}

build_ibex() {
    local work
    work=$(mktemp -d "$cache/build.XXXXXX")
    trap 'rm -rf "$work"' RETURN
    echo "make dreal: building IBEX $IBEX_VERSION into $prefix (about 10 minutes on 2 cores; once per machine)"
    tar xzf "$IBEX_SRC" -C "$work"
    cd "$work"/ibex-lib-*
    # The bundled waf (2.0.12) opens files with mode 'rU', which Python 3.11 refuses: its first run unpacks waflib
    # into a hidden .waf3-* folder, where 'rU' is read as 'r' (what it meant).
    "$PYTHON" waf --version >/dev/null
    grep -rlZ "'rU'" .waf3-*/waflib | xargs -0 -r sed -i "s/'rU'/'r'/g"
    rm -rf "$prefix"
    # --with-optim: without it dReal fails to load (undefined symbol ibex::LoupFinderInHC4::add_property).
    # The soname: IBEX's waf sets none, and without one the dynamic linker does not take the library
    # dreal_backend.py loads by path for the wheel's NEEDED libibex.so.
    LINKFLAGS="-Wl,-soname,libibex.so" nice "$PYTHON" waf configure --enable-shared --with-optim --interval-lib=filib --lp-lib=clp --prefix="$prefix" >build.log 2>&1 \
        || { tail -30 build.log >&2; die "IBEX configure failed (log above)"; }
    nice "$PYTHON" waf build -j "${JOBS:-2}" >>build.log 2>&1 || { tail -30 build.log >&2; die "IBEX build failed (log above)"; }
    "$PYTHON" waf install >>build.log 2>&1 || { tail -30 build.log >&2; die "IBEX install failed (log above)"; }
    cd - >/dev/null
    test -f "$lib" || die "IBEX installed no $lib"
    echo "$RECIPE" >"$prefix/.complete"
}

mkdir -p "$cache"
install_packages
# One build at a time per prefix (two checkouts on one machine share the cache); the .complete stamp is written
# last, so an interrupted build is redone rather than trusted.
exec 9>"$prefix.lock"
flock 9
built || build_ibex
flock -u 9

here=$(cd "$(dirname "$0")/.." && pwd)
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps -r "$here/requirements-dreal.lock"
marker=$("$VENV/bin/python" -c "from synth.smt.dreal_backend import LIBIBEX_MARKER; print(LIBIBEX_MARKER)")
printf '%s\n' "$lib" >"$VENV/$marker"
# The proof: dReal answers, loaded the way r2s loads it (no LD_LIBRARY_PATH).
env -u LD_LIBRARY_PATH "$VENV/bin/python" - "$lib" <<'PY' || die "dReal does not load (see above)"
import sys

from synth.smt.dreal_backend import load_dreal

dreal = load_dreal()
x = dreal.Variable("x")
assert dreal.CheckSatisfiability(dreal.And(x * x == 2.0, x > 0), 1e-3) is not None
print(f"make dreal: dReal {dreal.__version__} answers, with {sys.argv[1]}")
PY
