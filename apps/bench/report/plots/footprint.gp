# hermd's idle footprint next to reference processes and the targets:
# CPU (% of one core) and resident memory, median of runs, whiskers min..max.
# Variables: datadir, out, cpu_target, rss_target, cpu_max, rss_max, nproc; datadir/footprint.dat.
load sprintf('%s/common.gp', system('dirname "' . ARG0 . '"'))
set multiplot layout 1,2 title "Idle processes: CPU and memory (median of runs, whiskers min..max)" font 'sans,13'
set boxwidth 0.6
set xrange [-0.6:nproc - 0.4]
set key off
set xtics rotate by -25
set title 'CPU while idle'
set ylabel '% of one core'
set yrange [0:cpu_max]
set arrow 1 from graph 0, first cpu_target to graph 1, first cpu_target nohead dt 2 lw 2 lc rgb '#c00000'
set label 1 sprintf('target < %g %%', cpu_target) at graph 0.02, first cpu_target * 1.04 tc rgb '#c00000'
plot datadir.'/footprint.dat' skip 1 using 0:2:3:4:(0.6):xtic(1) with boxerrorbars lc rgb '#1f77b4'
unset arrow 1
unset label 1
set title 'resident memory (VmRSS)'
set ylabel 'MiB'
set yrange [0:rss_max]
set arrow 2 from graph 0, first rss_target to graph 1, first rss_target nohead dt 2 lw 2 lc rgb '#c00000'
set label 2 sprintf('target < %g MiB', rss_target) at graph 0.02, first rss_target * 1.04 tc rgb '#c00000'
plot datadir.'/footprint.dat' skip 1 using 0:5:6:7:(0.6):xtic(1) with boxerrorbars lc rgb '#ff7f0e'
unset multiplot
