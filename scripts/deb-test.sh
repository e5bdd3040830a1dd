#!/usr/bin/env bash
# Builds the Debian package from the release build (features camera,ros2: the robot's) with
# cargo-deb, installs it on this machine with apt-get and checks the install as a robot's
# would be: the installed binary accepts the installed configuration, the installed systemd
# unit verifies, the service is neither enabled nor started, `dpkg -r` keeps an edited
# configuration and `dpkg --purge` removes it. Leaves the machine without the package.
# Needs root (or sudo) and Debian's apt. Called by .ci/run after its release build, which it
# reuses (`cargo deb --no-build`). Usage: scripts/deb-test.sh
set -euo pipefail
cd "$(dirname "$0")/.."

CARGO_DEB_VERSION=3.8.0
sudo=""
[ "$(id -u)" = 0 ] || sudo="sudo"

if ! cargo deb --version 2>/dev/null | grep -q "$CARGO_DEB_VERSION"; then
  # A debug build of the tool: half the build time, and packaging takes as long with it.
  cargo install --locked --quiet --debug cargo-deb --version "$CARGO_DEB_VERSION"
fi
# dpkg-shlibdeps (dpkg-dev) computes the package's library dependencies ($auto).
command -v dpkg-shlibdeps >/dev/null || {
  $sudo apt-get update -qq
  $sudo apt-get install -y --no-install-recommends dpkg-dev
}

# The robot's build; a no-op after .ci/run's build with every feature (camera and ros2 are
# all the features there are).
cargo build --release --locked --all-features
rm -f target/debian/omnirow_*.deb
cargo deb --no-build --locked --strip
deb=$(ls target/debian/omnirow_*.deb)
echo "deb-test: built $deb"
dpkg-deb --info "$deb" | sed -n '/Depends/p'

fail() { echo "deb-test: FAILED: $*" >&2; exit 1; }
# Whatever happens, the machine is left without the package.
trap '$sudo dpkg --purge omnirow >/dev/null 2>&1 || true' EXIT
$sudo dpkg --purge omnirow >/dev/null 2>&1 || true

$sudo apt-get install -y --no-install-recommends "./$deb"
for f in /usr/bin/omnirow /etc/omnirow/omnirow.toml /usr/lib/systemd/system/omnirow.service \
  /etc/systemd/network/70-omnirow-camera.link /etc/udev/rules.d/70-omnirow-camera.rules \
  /usr/lib/sysctl.d/90-omnirow-gige.conf /usr/share/omnirow/calib/fisheye185_gc2450c.toml \
  /usr/share/doc/omnirow/README.md /usr/share/doc/omnirow/copyright; do
  [ -e "$f" ] || fail "$f not installed"
done
dpkg-query -W -f='${Conffiles}\n' omnirow | grep -q ' /etc/omnirow/omnirow.toml ' ||
  fail "/etc/omnirow/omnirow.toml is not a conffile"
/usr/bin/omnirow config check /etc/omnirow/omnirow.toml
/usr/bin/omnirow detect --help >/dev/null
if command -v systemd-analyze >/dev/null; then
  systemd-analyze verify /usr/lib/systemd/system/omnirow.service
  echo "deb-test: systemd-analyze verify passed on the installed unit"
fi
[ ! -e /etc/systemd/system/multi-user.target.wants/omnirow.service ] ||
  fail "the package enabled the service"
if [ -d /run/systemd/system ] && systemctl is-active --quiet omnirow.service; then
  fail "the package started the service"
fi

# An edited configuration survives `dpkg -r`, and `dpkg --purge` removes it.
echo "# edited by deb-test" | $sudo tee -a /etc/omnirow/omnirow.toml >/dev/null
$sudo dpkg -r omnirow
[ ! -e /usr/bin/omnirow ] || fail "dpkg -r left /usr/bin/omnirow"
grep -q "edited by deb-test" /etc/omnirow/omnirow.toml || fail "dpkg -r lost the edited configuration"
$sudo dpkg --purge omnirow
[ ! -e /etc/omnirow/omnirow.toml ] || fail "dpkg --purge left /etc/omnirow/omnirow.toml"
[ ! -e /etc/omnirow ] || fail "dpkg --purge left /etc/omnirow"
echo "deb-test: ok ($deb: installed, checked, removed, purged)"
