#!/usr/bin/env bash
# Host-side checks of tools/run (it cannot test itself from inside): the command
# runs in the caller's folder, outside the repository, sees the caller's
# environment, writes where the caller can read, passes its exit status
# through, and mpirun works there. Runs in the suite DOLFINX_MORTAR_SUITE
# (as tools/run does). Prints "N passed, M failed"; exits 1 on a failure.
#   tests/tools/test_run.sh
set -uo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
run=$repo/tools/run
passed=0
failed=0

check() {
    local name=$1
    shift
    if "$@"; then
        passed=$((passed + 1))
        echo "ok: $name"
    else
        failed=$((failed + 1))
        echo "FAIL: $name"
    fi
}

# a folder outside the repository and outside /tmp, and one in /tmp for output
base=${XDG_CACHE_HOME:-$HOME/.cache}
mkdir -p "$base" || exit 1
work=$(mktemp -d "$base/dolfinx-mortar-test-run.XXXXXX") || exit 1
out=$(mktemp -d /tmp/dolfinx-mortar-test-run.XXXXXX) || exit 1
trap 'rm -rf "$work" "$out"' EXIT
case "$work" in "$repo"/*) echo "test folder $work is inside the repository" >&2; exit 1 ;; esac

cat >"$work/script.py" <<'EOF'
"""Writes what it sees to --json: versions, folder, environment, a relative file."""

import argparse
import json
import os
import sys

import dolfinx
import dolfinx_mortar

parser = argparse.ArgumentParser()
parser.add_argument("--json", required=True)
args = parser.parse_args()
with open("input.txt") as f:
    relative = f.read().strip()
with open("output.txt", "w") as f:
    f.write("written inside\n")
summary = {
    "dolfinx": dolfinx.__version__,
    "dolfinx_mortar": os.path.dirname(dolfinx_mortar.__file__),
    "cwd": os.getcwd(),
    "my_var": os.environ.get("MY_VAR"),
    "relative": relative,
    "home": os.environ.get("HOME"),
    "pythonhome": os.environ.get("PYTHONHOME"),
    "sys_path": sys.path,
    "no_user_site": sys.flags.no_user_site,
    "cache": os.environ.get("XDG_CACHE_HOME"),
    "scotch_threads": os.environ.get("SCOTCH_PTHREAD_NUMBER"),
}
with open(args.json, "w") as f:
    json.dump(summary, f)
EOF
echo "read from the caller's folder" >"$work/input.txt"

json_is() {
    # json_is FILE PYTHON-EXPRESSION-ON-d: true when it holds
    python3 -c "import json, sys; d = json.load(open(sys.argv[1])); sys.exit(0 if ($2) else 1)" "$1"
}

# in the Debian root, DOLFINX_MORTAR_SUITE is set inside; on a host with dolfinx, not
cd "$work" || exit 1
suite=$("$run" python3 -c "import os; print(os.environ.get('DOLFINX_MORTAR_SUITE', ''))")
if [ -n "$suite" ]; then
    echo "tools/run uses the Debian $suite root"
    check "in the suite asked for ($suite)" test "$suite" = "${DOLFINX_MORTAR_SUITE:-trixie}"
    # dropped inside the root: it would point the root's python at the host's
    dropped=(PYTHONHOME=/nonexistent)
else
    echo "tools/run uses the host's python"
    dropped=()
fi

env MY_VAR=hello PYTHONPATH=/caller/extra "${dropped[@]}" \
    "$run" python3 script.py --json "$out/x.json" >"$out/script.log" 2>&1
status=$?
[ $status -eq 0 ] || { echo "script.py failed (exit $status):"; cat "$out/script.log"; }
check "script.py outside the repository runs (exit $status)" test $status -eq 0
check "its --json in /tmp is readable afterwards" test -s "$out/x.json"
version=$(python3 -c "import json, sys; print(json.load(open(sys.argv[1]))['dolfinx'])" \
    "$out/x.json" 2>/dev/null)
check "it imports dolfinx >= 0.9 (${version:-none})" json_is "$out/x.json" \
    'tuple(int(v) for v in d["dolfinx"].split(".")[:2]) >= (0, 9)'
check "it imports dolfinx_mortar from the repository" json_is "$out/x.json" \
    "d['dolfinx_mortar'] == '$repo/dolfinx_mortar'"
check "it runs in the caller's folder" json_is "$out/x.json" "d['cwd'] == '$work'"
check "it reads a relative path in the caller's folder" json_is "$out/x.json" \
    "d['relative'] == 'read from the caller\\'s folder'"
check "it writes a relative path in the caller's folder" grep -qx "written inside" "$work/output.txt"
check "it sees MY_VAR exported by the caller" json_is "$out/x.json" "d['my_var'] == 'hello'"
check "it keeps the caller's HOME" json_is "$out/x.json" "d['home'] == '$HOME'"
# one PT-Scotch thread: the same mesh is partitioned the same way in every run
if [ -z "${SCOTCH_PTHREAD_NUMBER+x}" ]; then
    check "PT-Scotch runs one thread (SCOTCH_PTHREAD_NUMBER=1)" json_is "$out/x.json" \
        "d['scotch_threads'] == '1'"
fi
threads=$(cd "$work" && SCOTCH_PTHREAD_NUMBER=2 "$run" sh -c 'echo "$SCOTCH_PTHREAD_NUMBER"')
check "the caller's SCOTCH_PTHREAD_NUMBER wins (2, got $threads)" test "$threads" = 2
if [ -n "$suite" ]; then
    check "PYTHONHOME is dropped" json_is "$out/x.json" "d['pythonhome'] is None"
    check "the host's ~/.local packages are not imported" json_is "$out/x.json" "d['no_user_site']"
    check "caches (FFCx JIT) stay in the root" json_is "$out/x.json" \
        "d['cache'] == '/var/cache/dolfinx-mortar'"
fi
check "PYTHONPATH is the repository, then the caller's" json_is "$out/x.json" \
    "d['sys_path'].index('$repo') < d['sys_path'].index('/caller/extra')"

# an absolute script path from another folder
cd "$out" || exit 1
rm -f "$out/y.json"
"$run" python3 "$work/script.py" --json "$out/y.json" >/dev/null 2>&1
check "python3 /absolute/script.py from another folder fails on its relative input" \
    test ! -e "$out/y.json"
echo "another folder" >"$out/input.txt"
"$run" python3 "$work/script.py" --json y.json >/dev/null 2>&1
check "python3 /absolute/script.py from another folder runs there" json_is "$out/y.json" \
    "d['cwd'] == '$out' and d['relative'] == 'another folder'"

# exit status
cd "$work" || exit 1
"$run" python3 -c "raise SystemExit(7)" 2>/dev/null
status=$?
check "a failing command's status comes back (7, got $status)" test $status -eq 7
"$run" sh -c "exit 0"
status=$?
check "a succeeding command's status comes back (0, got $status)" test $status -eq 0

# mpirun from the outside folder, two at the same time (shared /tmp)
mpi_code='
import os, sys
from mpi4py import MPI
comm = MPI.COMM_WORLD
ranks = comm.allgather((comm.rank, os.getcwd()))
if comm.rank == 0:
    with open(sys.argv[1], "w") as f:
        f.write(repr(sorted(ranks)))
'
for i in 1 2; do
    timeout --kill-after=30 600 "$run" mpirun -n 2 python3 -c "$mpi_code" "$out/mpi$i.txt" \
        >"$out/mpi$i.log" 2>&1 &
done
wait
for i in 1 2; do
    expected="[(0, '$work'), (1, '$work')]"
    if [ "$(cat "$out/mpi$i.txt" 2>/dev/null)" != "$expected" ]; then cat "$out/mpi$i.log"; fi
    check "mpirun -n 2 (run $i of 2 at once): both ranks in the caller's folder" \
        test "$(cat "$out/mpi$i.txt" 2>/dev/null)" = "$expected"
done

# where the Debian root cannot share the folder, tools/run refuses
if [ -n "$suite" ]; then
    for folder in / /usr /etc; do
        cd "$folder" || exit 1
        message=$("$run" true 2>&1)
        status=$?
        check "refuses to run in $folder (64, got $status)" test $status -eq 64
        check "says why in $folder" grep -q "^tools/run: cannot run in $folder" <<<"$message"
    done
fi

echo "$passed passed, $failed failed"
[ $failed -eq 0 ]
