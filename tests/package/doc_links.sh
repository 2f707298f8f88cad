#!/usr/bin/env bash
# Every relative link in the documentation the package installs leads to a file the package
# installs. The docs are written in the repository, where a link such as
# `../systemd/README.md` works; installed under /usr/share/doc/surfscan/ they only work when the
# package keeps the repository's layout there. deb.sh runs this on the installed package; run it
# by hand on an unpacked one: `dpkg-deb -x surfscan_*.deb /tmp/x && tests/package/doc_links.sh /tmp/x`.
#
# Usage: doc_links.sh [ROOT]   (ROOT is where the package is unpacked; / when installed)
# Prints each broken link as `FILE: LINK` and exits 1 when there is one.
set -euo pipefail
root=${1:-/}
doc="${root%/}/usr/share/doc/surfscan"
[ -d "$doc" ] || {
  echo "doc_links.sh: $doc does not exist: is the package installed (or unpacked under $root)?" >&2
  exit 2
}

# Links into parts of the repository that a station does not get, each for a reason: the
# simulator and the test data are development tools; the changelog is installed as Debian
# wants it (changelog.gz); the example configuration is installed as /etc/surfscan/surfscan.toml;
# CONTRIBUTING.md is for developers of surfscan. Paths relative to the repository's root.
repository_only="CHANGELOG.md CONTRIBUTING.md config/surfscan.toml simulator/README.md tests/data/README.md"

broken=0
while IFS= read -r md; do
  dir=$(dirname "$md")
  while IFS= read -r link; do
    target=${link%%#*}
    case $target in "" | http://* | https://* | mailto:*) continue ;; esac
    resolved=$(realpath -m "$dir/$target")
    [ -e "$resolved" ] && continue
    in_repo=${resolved#"$(realpath -m "$doc")"/}
    [[ " $repository_only " == *" $in_repo "* ]] && continue
    echo "${md#"${root%/}"}: $link"
    broken=$((broken + 1))
  done < <(grep -o '](\([^) ]*\))' "$md" | sed 's/^](//; s/)$//')
done < <(find "$doc" -name '*.md' | sort)
[ "$broken" -eq 0 ] || {
  echo "doc_links.sh: $broken links in the installed docs lead nowhere; install their targets at the repository's paths (Cargo.toml, [package.metadata.deb] assets) or list them above as repository-only" >&2
  exit 1
}
