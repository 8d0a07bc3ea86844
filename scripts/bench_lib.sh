# Sourced by the benchmark scripts (bench_tile.sh, bench_terrain.sh,
# bench_readers.sh, bench_warp.sh): what they share.

# median: the median of the numbers on standard input (one per line, or
# separated by spaces); "nan" when there are none.
median() {
  tr ' ' '\n' | grep -v '^$' | sort -g |
    awk '{a[NR]=$1} END {if (NR==0) print "nan"; else if (NR%2) print a[(NR+1)/2]; else print (a[NR/2]+a[NR/2+1])/2}'
}
