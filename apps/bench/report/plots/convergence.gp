# Routing cold start against module count: simulated time to converge, and
# the routing traffic it takes per module. Deterministic (one run).
# Variables: datadir, out; datadir/convergence.dat.
load sprintf('%s/common.gp', system('dirname "' . ARG0 . '"'))
set multiplot layout 1,2 title "Routing cold start on random meshes (simulated time, hello 100 ms)" font 'sans,13'
set logscale x
set xlabel 'modules (log scale)'
set key bottom right font 'sans,10'
set title "time until every module routes to every other\n(checked every half hello interval)"
set ylabel 'converged after (ms, simulated)'
set yrange [0:*]
set offsets 0, 0, graph 0.1, 0
plot datadir.'/convergence.dat' using 1:2 with linespoints lw 2 pt 7 lc rgb '#1f77b4' title 'convergence time'
set title 'routing traffic per module until then'
set ylabel 'per module (log scale)'
set logscale y
set offsets 0, 0, 0, 0
set yrange [*:*]
plot datadir.'/convergence.dat' using 1:3 with linespoints lw 2 pt 7 lc rgb '#ff7f0e' title 'update packets sent', \
     '' using 1:4 with linespoints lw 2 pt 5 lc rgb '#2ca02c' title 'update entries sent'
unset multiplot
