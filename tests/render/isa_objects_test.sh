#!/usr/bin/env bash
# ctest "render_isa_objects": the AVX-512 compilation of the rasterizer kernels (render/raster_isa.h) holds
# AVX-512 code only in functions of its own namespace (hgs::render::avx512). Any other function in those object
# files (an out-of-line copy of a header's inline function or template) is shared by name with the portable
# compilation, and the linker may keep either copy for the whole program: with AVX-512 instructions in it the
# portable path would crash on a CPU without AVX-512, which no other test can see on a machine that has it.
# AVX-512 code is recognised by what only EVEX encodes: zmm registers, ymm/xmm 16-31, mask registers k1-k7.
# Usage: isa_objects_test.sh OBJECT... Exits 77 (skipped) without objdump.
set -euo pipefail
command -v objdump >/dev/null 2>&1 || { echo "skip: objdump (binutils) is not installed"; exit 77; }
[ $# -gt 0 ] || { echo "usage: $0 OBJECT..." >&2; exit 2; }
status=0
evex_functions=0
for obj in "$@"; do
  report=$(objdump -d -C --no-show-raw-insn "$obj" | awk '
    /^[0-9a-f]+ <.*>:$/ { name = $0; next }
    /%zmm|%[xy]mm(1[6-9]|2[0-9]|3[01])|%k[1-7]/ {
      if (name ~ /hgs::render::avx512::/) { if (!(name in seen)) { seen[name] = 1; ++own } }
      else if (!(name in bad)) { bad[name] = 1; print "outside the namespace: " name }
    }
    END { print "own " own + 0 }')
  if grep -q "^outside" <<<"$report"; then
    echo "$obj:"; grep "^outside" <<<"$report"; status=1
  fi
  evex_functions=$((evex_functions + $(sed -n 's/^own //p' <<<"$report")))
done
# The check must see AVX-512 code at all (else it would pass on objects built without it).
[ "$evex_functions" -gt 0 ] || { echo "no AVX-512 code found in the kernels: were they compiled for AVX-512?"; exit 1; }
[ $status -eq 0 ] && echo "ok: AVX-512 code in $evex_functions kernel functions, all in hgs::render::avx512"
exit $status
