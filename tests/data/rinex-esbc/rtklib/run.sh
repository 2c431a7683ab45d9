#!/bin/sh
# Regenerates the RTKLIB reference solutions l1.pos and if.pos from the files of ../ with
# Debian's rtklib package (rnx2rtkp, RTKLIB 2.4.3 b34): single-point positioning, GPS only,
# broadcast ephemerides, elevation mask 10°, Saastamoinen troposphere, and either the
# broadcast Klobuchar ionosphere on L1 C/A (spp-l1.conf) or the L1/L2 ionosphere-free code
# combination (spp-if.conf; RTKLIB picks C1C on L1 and C2W on L2 by its code priorities).
# Usage: sh run.sh [output-directory]   (default: this directory)
set -eu
here=$(cd "$(dirname "$0")" && pwd)
out=${1:-$here}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
gzip -dc "$here/../ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz" > "$tmp/obs.rnx"
gzip -dc "$here/../ESBC00DNK_R_20201770000_01D_GN.rnx.gz" > "$tmp/nav.rnx"
out=$(cd "$out" && pwd)
cd "$tmp"
rnx2rtkp -k "$here/spp-l1.conf" -o "$out/l1.pos" obs.rnx nav.rnx 2>/dev/null
rnx2rtkp -k "$here/spp-if.conf" -o "$out/if.pos" obs.rnx nav.rnx 2>/dev/null
