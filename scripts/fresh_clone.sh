#!/usr/bin/env bash
# The newcomer's path (issue 50; docs/build.md): a fresh clone with a fresh HOME and TMPDIR runs
# README's commands exactly as written (the demo, the tests, `cargo install`, then
# `pip install "./python[images]"` and README's Python example), timing each and saying what
# they printed on stderr and what they left outside the clone.
#
# usage: scripts/fresh_clone.sh WORKDIR [COMMIT]     (WORKDIR is emptied; COMMIT: default HEAD)
# The toolchain stays where it is (CARGO_HOME, RUSTUP_HOME), as on a machine where Rust is
# installed; ../shared is linked beside the clone when this clone has one.
set -u
here=$(cd "$(dirname "$0")/.." && pwd)
B=$1; C=${2:-HEAD}
rm -rf "$B"; mkdir -p "$B/home" "$B/tmp"
B=$(cd "$B" && pwd)
git clone -q "$here" "$B/gpustar" && git -C "$B/gpustar" checkout -q "$(git -C "$here" rev-parse "$C")"
[ -d "$here/../shared" ] && ln -s "$(cd "$here/../shared" && pwd)" "$B/shared"
touch "$B/stamp"
cd "$B/gpustar"
E=(env -i HOME="$B/home" TMPDIR="$B/tmp" PATH="${CARGO_HOME:-$HOME/.cargo}/bin:/usr/local/bin:/usr/bin:/bin"
   CARGO_HOME="${CARGO_HOME:-$HOME/.cargo}" RUSTUP_HOME="${RUSTUP_HOME:-$HOME/.rustup}" TERM=dumb)
[ -n "${PYENV_ROOT:-}" ] && E+=(PYENV_ROOT="$PYENV_ROOT" PATH="$PYENV_ROOT/shims:${CARGO_HOME:-$HOME/.cargo}/bin:/usr/local/bin:/usr/bin:/bin")
line_after() { sed -n "/^# $1/{n;p}" README.md; }
step() {  # step NAME COMMAND: time it, keep its stdout and stderr
  echo "== $1: $2"; uptime
  /usr/bin/time -f "$1: %e s wall, %U s user, %S s system" "${E[@]}" bash -c "$2" >"$B/$1.out" 2>"$B/$1.err"
  echo "$1: exit $?"; tail -1 "$B/$1.err"
  echo "$1: stderr lines other than cargo's progress: $(grep -cvE '^ +(Compiling|Checking|Finished|Running|Doc-tests|Downloaded|Downloading|Installing|Installed|Replacing|Replaced|Locking|Updating)|: [0-9.]+ s wall' "$B/$1.err")"
  echo "$1: error lines: $(grep -ciE '^error' "$B/$1.err")"
}
step demo "$(line_after 'Solve 20 built-in')"
step tests "$(line_after 'Run the tests')"
step install "CARGO_INSTALL_ROOT=$B/installed $(line_after 'Put `gpustar` on PATH')"
"${E[@]}" python3 -m venv "$B/venv"
step pip "$B/venv/bin/pip install -q \"./python[images]\""
python3 - README.md >"$B/example.py" <<'PY'
import sys
s = open(sys.argv[1]).read()
s = s[s.index("## Python\n"):]
s = s[s.index("```python\n") + 10:]
print(s[:s.index("```")])
PY
mkdir -p "$B/example" && (cd "$B/example" && step example "$B/venv/bin/python $B/example.py")
echo "== disk"
# One at a time: du counts a folder once, so a folder listed after its parent would be skipped.
for d in target target/debug target/debug/incremental target/release target/gpustar-cache python/target; do
  [ -e "$d" ] && du -sh "$d"
done
echo "== outside the clone: HOME ($(du -sh "$B/home" | cut -f1)), TMPDIR ($(du -sh "$B/tmp" | cut -f1))"
(cd "$B/home" && find . -mindepth 1 -maxdepth 3)
ls "$B/tmp"
