# Round trip p50 per transport and size, one panel per mode; bars are the
# median of the runs' p50, whiskers its min..max over the runs.
# Variables: datadir, out, nsizes, nmodes; datadir/rttI.dat, and per mode a
# line of datadir/rtt.modes: MODE NSERIES COLOUR...
load sprintf('%s/common.gp', system('dirname "' . ARG0 . '"'))
set terminal pngcairo size 1000,(400 * nmodes + 70) font 'sans,11' noenhanced
set output out
set multiplot layout nmodes,1 title "Request round trip on 127.0.0.1: p50 (median of runs), whiskers min..max of the runs' p50" font 'sans,13'
set style data histograms
set style histogram errorbars gap 2 lw 1
set boxwidth 0.9
set logscale y
set ylabel 'round trip p50 (µs, log scale)'
set xrange [-0.6:nsizes - 0.4]
set key outside below horizontal maxrows 2 font 'sans,10'
do for [m = 0:nmodes - 1] {
  meta = system(sprintf("sed -n %dp '%s/rtt.modes'", m + 1, datadir))
  set title word(meta, 1)
  plot for [i = 0:int(word(meta, 2)) - 1] sprintf('%s/rtt%d.dat', datadir, m) \
       using (column(2 + 3 * i)):(column(3 + 3 * i)):(column(4 + 3 * i)):xtic(1) \
       title columnheader(2 + 3 * i) lc rgb word(meta, 3 + i)
}
unset multiplot
