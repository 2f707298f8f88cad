#!/usr/bin/env bash
# The station's Debian package end to end, on this Debian machine, as root (CI runs it from
# .ci/run): build it (packaging/build-deb), lintian without errors, install it with dpkg, check
# the files, that every relative link in the installed docs leads to an installed file
# (doc_links.sh), conffiles, user, groups, directories and the unit (`systemd-analyze verify`),
# `surfscan --version` and `check-config` of the installed example; upgrade to a scratch copy
# with the version bumped and a changed shipped configuration, over an edited one, and check
# the edit and a scan survive; remove, then purge, and check what stays (the scans, the user)
# and what goes (the binary, the configuration).
#
# Not covered here: starting, enabling for real and restarting the service, which need systemd
# as PID 1 (a CI container has none); the unit's enablement is checked as the symlink
# deb-systemd-helper makes.
#
# It installs into this machine's system, so it refuses to run where surfscan is installed or
# /etc/surfscan exists (a real station), and puts back what it changed when it ends, also on
# failure: the package purged, its test scan, and the user, group and /var/lib/surfscan when it
# created them.
set -euo pipefail
cd "$(dirname "$0")/../.."

say() { echo "deb.sh: $*"; }
checks=0
ok() {
  checks=$((checks + 1))
  say "ok: $*"
}
fail() {
  say "FAIL: $*" >&2
  exit 1
}

[ "$(id -u)" = 0 ] || fail "needs root: it installs and purges the package (CI runs as root)"
command -v lintian >/dev/null || fail "lintian is not installed (apt-get install lintian)"
exec 9>/run/lock/surfscan-deb-test.lock
flock -w 3600 9 || fail "another run of this test holds /run/lock/surfscan-deb-test.lock"
if dpkg-query -W -f='${Status}' surfscan 2>/dev/null | grep -q 'install ok\|config-files'; then
  fail "a surfscan package is on this machine (dpkg -l surfscan); this test installs and purges its own, so it runs only where there is none"
fi
[ ! -e /etc/surfscan ] || fail "/etc/surfscan exists: this looks like a station; the test would purge its configuration"

had_state=no
[ -e /var/lib/surfscan ] && had_state=yes
had_user=no
getent passwd surfscan >/dev/null && had_user=yes
had_group=no
getent group surfscan >/dev/null && had_group=yes
scratch=$(mktemp -d)
test_scan=/var/lib/surfscan/scans/deb-test-scan
cleanup() {
  local rc=$?
  if dpkg-query -W -f='${Status}' surfscan 2>/dev/null | grep -q 'install\|config-files'; then
    dpkg -P surfscan >/dev/null 2>&1 || true
  fi
  rm -rf "$test_scan" "$scratch"
  [ "$had_state" = yes ] || rm -rf /var/lib/surfscan
  [ "$had_user" = yes ] || userdel surfscan >/dev/null 2>&1 || true
  [ "$had_group" = yes ] || groupdel surfscan >/dev/null 2>&1 || true
  if [ "$rc" -eq 0 ]; then say "$checks passed, 0 failed"; else say "failed after $checks checks passed"; fi
}
trap cleanup EXIT

# --- build ------------------------------------------------------------------------------------
# build-deb prints the package's path last on standard output.
packaging/build-deb >"$scratch/build.out" 2>"$scratch/build.log" || {
  cat "$scratch/build.log" >&2
  fail "packaging/build-deb failed"
}
deb=$(tail -n 1 "$scratch/build.out")
[ -f "$deb" ] || fail "packaging/build-deb did not print the package's path: $(cat "$scratch/build.out")"
version=$(dpkg-deb -f "$deb" Version)
upstream=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n 1)
[ "$version" = "$upstream-1" ] || fail "the package's version $version is not the crate's $upstream with revision 1"
ok "built $deb"

# --- lintian ----------------------------------------------------------------------------------
# Errors fail the test; warnings and notes are printed for the record.
if ! lintian --fail-on error --tag-display-limit 0 "$deb" >"$scratch/lintian.txt" 2>&1; then
  cat "$scratch/lintian.txt" >&2
  fail "lintian reports errors on $deb"
fi
sed 's/^/  lintian: /' "$scratch/lintian.txt"
ok "lintian: no errors"

# --- the package's contents -------------------------------------------------------------------
dpkg-deb -c "$deb" >"$scratch/contents.txt"
if grep -q 'surfscan-sim' "$scratch/contents.txt"; then fail "the station package contains the simulator"; fi
ok "the simulator is not in the station package"

# --- install ----------------------------------------------------------------------------------
dpkg -i "$deb" >"$scratch/install.log" 2>&1 || {
  cat "$scratch/install.log" >&2
  fail "dpkg -i $deb failed"
}
ok "installed with dpkg -i"

for f in /usr/bin/surfscan \
  /usr/lib/systemd/system/surfscan.service \
  /usr/lib/sysusers.d/surfscan.conf \
  /usr/lib/tmpfiles.d/surfscan.conf \
  /usr/share/doc/surfscan/examples/99-surfscan.rules \
  /etc/surfscan/surfscan.toml \
  /etc/surfscan/recipes/example.toml \
  /usr/share/man/man1/surfscan.1.gz \
  /usr/share/man/man1/surfscan-check-config.1.gz \
  /usr/share/man/man1/surfscan-daemon.1.gz \
  /usr/share/bash-completion/completions/surfscan \
  /usr/share/zsh/vendor-completions/_surfscan \
  /usr/share/fish/vendor_completions.d/surfscan.fish \
  /usr/share/doc/surfscan/copyright \
  /usr/share/doc/surfscan/changelog.gz \
  /usr/share/doc/surfscan/README.md \
  /usr/share/doc/surfscan/docs/operator-guide.md \
  /usr/share/doc/surfscan/systemd/README.md; do
  [ -f "$f" ] || fail "$f is not installed"
done
[ ! -e /etc/udev/rules.d/99-surfscan.rules ] || fail "the package installed the udev rule into /etc/udev/rules.d, the administrator's directory"
ok "binary, unit, sysusers, tmpfiles, configuration, recipe, man pages, completions, docs and the example udev rule are in place"

tests/package/doc_links.sh / || fail "links in the installed documentation lead to files the package does not install (above)"
ok "every relative link in the installed documentation leads to an installed file"

cmp -s config/surfscan.toml /etc/surfscan/surfscan.toml || fail "/etc/surfscan/surfscan.toml is not the shipped example"
zcat /usr/share/man/man1/surfscan-check-config.1.gz | grep -q -- 'require\\-devices' \
  || fail "the installed man page of check-config does not describe --require-devices"
bash -c 'source /usr/share/bash-completion/completions/surfscan && complete -p surfscan' >/dev/null \
  || fail "the bash completion does not register for surfscan"
ok "the example configuration is the repository's; the man page and the bash completion come from this binary"

conffiles=$(dpkg-query -W -f='${Conffiles}\n' surfscan)
for f in /etc/surfscan/surfscan.toml /etc/surfscan/recipes/example.toml; do
  grep -q " $f " <<<"$conffiles" || fail "$f is not a conffile: $conffiles"
done
ok "the configuration and the recipe are conffiles"

# --- user, groups, directories ----------------------------------------------------------------
IFS=: read -r _ _ _ _ _ home shell <<<"$(getent passwd surfscan)" || fail "no user surfscan"
[ "$home" = /var/lib/surfscan ] || fail "user surfscan's home is $home"
[ "$shell" = /usr/sbin/nologin ] || fail "user surfscan's shell is $shell"
groups=" $(id -nG surfscan) "
[[ $groups == *" surfscan "* && $groups == *" dialout "* ]] || fail "user surfscan is in groups$groups; wants surfscan and dialout"
ok "system user surfscan (home /var/lib/surfscan, no login) in groups surfscan and dialout"

[ "$(stat -c '%U:%G %a' /etc/surfscan)" = "root:surfscan 750" ] \
  || fail "/etc/surfscan is $(stat -c '%U:%G %a' /etc/surfscan); wants root:surfscan 750"
[ "$(stat -c '%U:%G %a' /var/lib/surfscan/scans)" = "surfscan:surfscan 750" ] \
  || fail "/var/lib/surfscan/scans is $(stat -c '%U:%G %a' /var/lib/surfscan/scans)"
ok "/etc/surfscan root:surfscan 750, /var/lib/surfscan/scans surfscan:surfscan 750 (tmpfiles.d)"

# --- the unit ---------------------------------------------------------------------------------
[ -L /etc/systemd/system/multi-user.target.wants/surfscan.service ] \
  || fail "the unit is not enabled (no multi-user.target.wants/surfscan.service)"
ok "the unit is enabled"
if ! systemd-analyze verify /usr/lib/systemd/system/surfscan.service >"$scratch/verify.txt" 2>&1 \
  || grep -q 'surfscan.service' "$scratch/verify.txt"; then
  cat "$scratch/verify.txt" >&2
  fail "systemd-analyze verify reports on the installed unit"
fi
ok "systemd-analyze verify: the installed unit is clean"

# --- the installed binary ---------------------------------------------------------------------
v=$(surfscan --version)
[[ $v == "surfscan $upstream"* ]] || fail "surfscan --version says '$v'"
if surfscan demo >/dev/null 2>&1; then fail "the station binary runs demo (the in-process simulator)"; fi
ok "surfscan --version: $v; no demo in the station binary"

surfscan check-config /etc/surfscan/surfscan.toml >"$scratch/check.out" 2>"$scratch/check.err" || {
  cat "$scratch/check.out" "$scratch/check.err" >&2
  fail "check-config of the installed example fails"
}
grep -q '^/etc/surfscan/surfscan.toml: valid' "$scratch/check.out" || fail "check-config: $(cat "$scratch/check.out")"
grep -q 'recipe      example' "$scratch/check.out" || fail "check-config does not list the example recipe: $(cat "$scratch/check.out")"
ok "check-config: the installed example and its recipe are valid"
# What the postinst asks before it starts the service on a first install: the example's ports
# are not on this machine, so the answer is no (69).
set +e
surfscan check-config --require-devices /etc/surfscan/surfscan.toml >/dev/null 2>"$scratch/check.err"
rc=$?
set -e
[ "$rc" = 69 ] || fail "check-config --require-devices exits $rc without the example's devices; wants 69"
grep -q 'port /dev/sj210 is not present now' "$scratch/check.err" || fail "$(cat "$scratch/check.err")"
ok "check-config --require-devices: 69 naming /dev/sj210 (a first install is not started)"

# --- upgrade over an edited configuration -----------------------------------------------------
sed -i 's#^port = "/dev/sj210"#port = "/dev/serial/by-id/usb-FTDI-deb-test-if00-port0"#' /etc/surfscan/surfscan.toml
grep -q 'deb-test' /etc/surfscan/surfscan.toml || fail "could not edit the installed configuration"
mkdir -p "$test_scan/lines"
echo "x_mm,z_um" >"$test_scan/lines/0000.csv"
chown -R surfscan:surfscan "$test_scan"

# A scratch copy of the package: version bumped, and its shipped configuration changed too, so
# that dpkg meets a conffile changed on both sides (the hard case).
dpkg-deb -R "$deb" "$scratch/next"
next_version="$upstream-2"
sed -i "s/^Version: .*/Version: $next_version/" "$scratch/next/DEBIAN/control"
echo "# shipped by $next_version" >>"$scratch/next/etc/surfscan/surfscan.toml"
(cd "$scratch/next" && find . -path ./DEBIAN -prune -o -type f -printf '%P\0' | sort -z | xargs -0 md5sum >DEBIAN/md5sums)
dpkg-deb --root-owner-group -b "$scratch/next" "$scratch/surfscan_${next_version}.deb" >/dev/null
# As unattended upgrades run it: keep the local edit, put the new shipped file beside it.
dpkg -i --force-confdef --force-confold "$scratch/surfscan_${next_version}.deb" >"$scratch/upgrade.log" 2>&1 || {
  cat "$scratch/upgrade.log" >&2
  fail "the upgrade to $next_version failed"
}
[ "$(dpkg-query -W -f='${Version}' surfscan)" = "$next_version" ] || fail "not upgraded to $next_version"
grep -q 'deb-test' /etc/surfscan/surfscan.toml || fail "the upgrade replaced the edited configuration"
grep -q "shipped by $next_version" /etc/surfscan/surfscan.toml.dpkg-dist \
  || fail "the new shipped configuration is not beside the edited one (surfscan.toml.dpkg-dist)"
[ -f "$test_scan/lines/0000.csv" ] || fail "the upgrade lost a scan"
[ -L /etc/systemd/system/multi-user.target.wants/surfscan.service ] || fail "the upgrade disabled the unit"
ok "upgrade to $next_version: the edited configuration kept (new one as .dpkg-dist), the scan and the enabled unit kept"

# An upgrade whose shipped configuration did not change keeps the edit without asking (no
# standard input: dpkg would fail at a prompt).
third_version="$upstream-3"
sed -i "s/^Version: .*/Version: $third_version/" "$scratch/next/DEBIAN/control"
dpkg-deb --root-owner-group -b "$scratch/next" "$scratch/surfscan_${third_version}.deb" >/dev/null
dpkg -i "$scratch/surfscan_${third_version}.deb" >"$scratch/upgrade3.log" 2>&1 </dev/null || {
  cat "$scratch/upgrade3.log" >&2
  fail "the upgrade to $third_version failed"
}
[ "$(dpkg-query -W -f='${Version}' surfscan)" = "$third_version" ] || fail "not upgraded to $third_version"
grep -q 'deb-test' /etc/surfscan/surfscan.toml || fail "the upgrade to $third_version replaced the edited configuration"
ok "upgrade to $third_version (shipped configuration unchanged): the edit kept without a prompt"

# --- remove, then purge -----------------------------------------------------------------------
dpkg -r surfscan >"$scratch/remove.log" 2>&1 || {
  cat "$scratch/remove.log" >&2
  fail "dpkg -r failed"
}
[ ! -e /usr/bin/surfscan ] || fail "remove left /usr/bin/surfscan"
[ ! -e /usr/lib/systemd/system/surfscan.service ] || fail "remove left the unit"
grep -q 'deb-test' /etc/surfscan/surfscan.toml || fail "remove deleted the configuration"
[ -f "$test_scan/lines/0000.csv" ] || fail "remove deleted a scan"
ok "remove: the program and unit gone; the configuration and the scans stay"

dpkg -P surfscan >"$scratch/purge.log" 2>&1 || {
  cat "$scratch/purge.log" >&2
  fail "dpkg -P failed"
}
[ ! -e /etc/surfscan ] || fail "purge left /etc/surfscan: $(ls -A /etc/surfscan)"
[ ! -e /etc/systemd/system/multi-user.target.wants/surfscan.service ] || fail "purge left the unit enabled"
[ -f "$test_scan/lines/0000.csv" ] || fail "purge deleted a scan in the output directory"
getent passwd surfscan >/dev/null || fail "purge removed the user that owns the scans"
ok "purge: the configuration and the enablement gone; the scans and their owner stay"
