# Shared set-up for scripts/demo.sh and scripts/test.sh (sourced, not run).
# Creates .venv with a Python >= 3.11 and installs lodconvert with the given extras; installs
# pinned npm packages into ./node_modules (git-ignored, never committed).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

apt_install() {
  # Debian packages, only those missing; quiet unless something goes wrong.
  command -v apt-get >/dev/null || { echo "apt-get not found: install $* yourself" >&2; return 0; }
  local missing=()
  for pkg in "$@"; do dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg"); done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "installing Debian packages: ${missing[*]}"
  as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

make_venv() {
  # $1: pip extras, e.g. "" or "[test]"
  local python="${PYTHON:-python3}"
  if [ ! -x .venv/bin/python ]; then
    "$python" -m venv .venv 2>/dev/null || { apt_install python3-venv; "$python" -m venv .venv; }
  fi
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e ".$1"
}

npm_install_pinned() {
  # $@: name@version pins. One `npm install --no-save` for all of them, and only when one is
  # missing or at another version (a later --no-save install would prune the others).
  local pin name stale=0
  for pin in "$@"; do
    name="${pin%@*}"
    [ "$(node -p "require('./node_modules/$name/package.json').version" 2>/dev/null)" = "${pin##*@}" ] || stale=1
  done
  [ $stale -eq 0 ] && return 0
  echo "installing npm packages: $*"
  npm install --no-save --no-audit --no-fund --silent --prefix . "$@"
}
