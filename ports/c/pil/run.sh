#!/bin/sh
# Every golden vector through the target under QEMU, with the instruction-counting plugin:
#   pil/run.sh QEMU MACHINE ELF PLUGIN OUT VECTOR.csv...
# OUT gets, per vector file, `file NAME`, the target's lines and the plugin's `law N` / `cycle N`
# lines. A vector file the target cannot read stops it with the target's one line and its status.
set -e
qemu=$1 machine=$2 elf=$3 plugin=$4 out=$5
shift 5
addr() { # a marker's entry address (a Thumb symbol's value has bit 0 set)
    v=$(arm-none-eabi-nm "$elf" | sed -n "s/^\([0-9a-f]*\) T $1\$/\1/p")
    printf '%x' $((0x$v & ~1))
}
marks="law=$(addr pil_law_begin):$(addr pil_law_end),cycle=$(addr pil_cycle_begin):$(addr pil_cycle_end)"
rm -f "$out.tmp"
for f in "$@"; do
    echo "file $(basename "$f")" >> "$out.tmp"
    "$qemu" -M "$machine" -nographic -monitor none -serial none -kernel "$elf" \
        -semihosting-config "enable=on,target=native,arg=pil,arg=${f%%__*}.cfg,arg=$f" \
        -plugin "$plugin,out=$out.cnt,$marks" >> "$out.tmp"
    grep -v '^total ' "$out.cnt" >> "$out.tmp"
done
rm -f "$out.cnt"
mv "$out.tmp" "$out"
