#!/usr/bin/env bash
# FMI4j (the JVM FMI library, Maven artifact info.laht.fmi4j:fmi-import:0.38.0), the importer
# tests/test_orchestrator/test_fmi4j.py replays the exported SSP with.  FMI4j 0.38 has no SSP
# loader of its own, so tests/tools/fmi4j/ holds a small Java harness (SspReplay: reads the
# SSD and SSV files, FMI4j loads and runs the FMUs, a Jacobi master steps them).
#
# Builds the harness once (`mvn -q package`, the dependencies from Maven Central into ~/.m2)
# into ${XDG_CACHE_HOME:-~/.cache}/fullpose/fmi4j-<hash of its sources>, prints the command
# prefix that runs it (`java -cp <classpath> SspReplay`, then SSP_PATH STOP_TIME OUT_CSV) and
# exits 0; or says on stderr why there is none (no java or mvn, the build failed) and exits 1
# (the tests then skip and say so).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
src="$here/fmi4j"

if ! command -v java >/dev/null 2>&1; then
    echo "no java on PATH: the FMI4j harness needs a JDK (11 or later) and Maven" >&2
    exit 1
fi
java=$(command -v java)

hash=$(cd "$src" && cat pom.xml src/main/java/SspReplay.java | sha256sum | cut -c1-16)
cache="${XDG_CACHE_HOME:-$HOME/.cache}/fullpose/fmi4j-$hash"

# built, and the dependencies it names still in the local Maven repository
ready() {
    [ -f "$cache/ready" ] || return 1
    local entry IFS=:
    for entry in $(cat "$cache/classpath.txt"); do [ -f "$entry" ] || return 1; done
}
prefix() {
    printf '%q -cp %q SspReplay\n' "$java" \
        "$cache/build/target/sspreplay-1.jar:$(cat "$cache/classpath.txt")"
}
if ready; then prefix; exit 0; fi
if ! command -v mvn >/dev/null 2>&1; then
    echo "no mvn on PATH: Maven builds the FMI4j harness (tests/tools/fmi4j) once" >&2
    exit 1
fi

mkdir -p "$(dirname "$cache")"
exec 9>"$(dirname "$cache")/fmi4j.lock"
flock 9 2>/dev/null || true  # one build at a time; the second finds it done
if ready; then prefix; exit 0; fi

work=$(mktemp -d "$cache.XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/build"
cp -R "$src/pom.xml" "$src/src" "$work/build/"
if ! (cd "$work/build" && mvn -q -B package >"$work/mvn.log" 2>&1 \
      && mvn -q -B dependency:build-classpath -Dmdep.outputFile="$work/classpath.txt" \
         >>"$work/mvn.log" 2>&1); then
    echo "the FMI4j harness did not build (mvn package in $src):" >&2
    tail -n 30 "$work/mvn.log" >&2
    exit 1
fi
rm -rf "$cache"
mv "$work" "$cache"
trap - EXIT
touch "$cache/ready"
prefix
