# Frame-time chart of one clipstream-fly run.
# Usage: gnuplot -e "csv='DIR/frames.csv'; png='OUT.png'" scripts/plot_frames.gp
# Top: frame time (ms) per frame. Bottom: tiles uploaded per frame and the
# MaxTextureLOD the shader was allowed (lower = sharper).
set datafile separator ","
if (strstrt(GPVAL_TERMINALS, "pngcairo") > 0) {
  set terminal pngcairo size 1200,800 font ",10"
} else {
  set terminal png size 1200,800
}
set output png
set multiplot layout 2,1 title "clipstream-fly: ".csv
set grid
set xrange [0:*]
set xlabel "frame"
set ylabel "ms"
plot csv using "frame":"frame_ms" with lines lw 1.5 title "frame ms", \
     csv using "frame":"draw_ms" with lines title "draw ms", \
     csv using "frame":"streamer_ms" with lines title "streamer ms"
set ylabel "tiles"
set y2label "level"
set y2tics 1
# From 0 up; a run that uploads nothing after its warm-up, or stays at
# level 0, still gets readable axes.
stats csv using "tiles_uploaded" name "UP" nooutput
stats csv using "max_texture_lod" name "LOD" nooutput
set yrange [0:(UP_max > 0 ? UP_max * 1.1 : 1)]
set y2range [0:LOD_max + 1]
set boxwidth 0.9 relative
set ytics nomirror
plot csv using "frame":"tiles_uploaded" with boxes fs solid 0.4 noborder title "tiles uploaded", \
     csv using "frame":"max_texture_lod" axes x1y2 with steps lw 2 title "MaxTextureLOD", \
     csv using "frame":"finest_needed" axes x1y2 with steps dt 2 title "finest level needed"
unset multiplot
