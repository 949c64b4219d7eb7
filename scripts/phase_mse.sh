#!/usr/bin/env bash
# How much harder a peaked phase function makes the estimate (docs/mathematics.md section 1.1):
# the MSE of one render of the benchmark (media_scenes/six_lights.toml with [medium] g set) at
# equal planes, for each g given, from the spread of independent seeds: for unbiased renders a
# and b, E|a - b|^2 = 2 MSE, averaged over PAIRS disjoint pairs of seeds. No reference needed
# (the reference renderer's equiangular samples ignore the phase function and are slow to
# converge in a peaked one).
#
#     scripts/phase_mse.sh [BINARY] [ESTIMATOR] [PLANES] [RESOLUTION] [PAIRS] -- G...
#     scripts/phase_mse.sh target/release/fogplanes smis-exact 40960 160x90 4 -- 0 0.8 0.95
set -euo pipefail
bin=${1:-target/release/fogplanes}; estimator=${2:-smis-exact}; planes=${3:-40960}
resolution=${4:-160x90}; pairs=${5:-4}
shift $(( $# < 5 ? $# : 5 )); [ "${1:-}" = "--" ] && shift
gs=("$@"); [ ${#gs[@]} -gt 0 ] || gs=(0 0.8 0.95)
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
for g in "${gs[@]}"; do
    sed "s/^sigma_a = \(.*\)$/sigma_a = \1\ng = $g/" media_scenes/six_lights.toml >"$tmp/six_lights.toml"
    sum=0; rel=0
    for ((p = 0; p < pairs; p++)); do
        for s in 1 2; do
            "$bin" render "$tmp/six_lights.toml" -e "$estimator" --planes "$planes" --resolution "$resolution" \
                --seed $((2 * p + s)) --quiet -o "$tmp/$s.exr" >/dev/null
        done
        out=$("$bin" compare "$tmp/1.exr" "$tmp/2.exr")
        sum=$(awk -v a="$sum" -v b="$(awk '/^MSE/{print $2}' <<<"$out")" 'BEGIN{print a + b}')
        rel=$(awk -v a="$rel" -v b="$(awk '/^relMSE/{print $2}' <<<"$out")" 'BEGIN{print a + b}')
    done
    awk -v g="$g" -v e="$estimator" -v n="$planes" -v s="$sum" -v r="$rel" -v p="$pairs" \
        'BEGIN{printf "g %5s  %s at %d planes: MSE %.3e, relMSE %.3e (one render, %d pairs of seeds)\n", g, e, n, s / (2 * p), r / (2 * p), p}'
done
