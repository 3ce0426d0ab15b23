# One-way throughput per transport and size: messages/s, median of runs,
# whiskers min..max. Variables: datadir, out, nsizes, nseries, colours;
# datadir/oneway.dat.
load sprintf('%s/common.gp', system('dirname "' . ARG0 . '"'))
set title "One-way throughput on 127.0.0.1 (median of runs, whiskers min..max)" font 'sans,13'
set style data histograms
set style histogram errorbars gap 2 lw 1
set boxwidth 0.9
set logscale y
set format y '%.0s %c'
set ylabel 'messages per second (log scale)'
set xrange [-0.6:nsizes - 0.4]
set key outside below horizontal maxrows 2 font 'sans,10'
plot for [i = 0:nseries - 1] sprintf('%s/oneway.dat', datadir) \
     using (column(2 + 3 * i)):(column(3 + 3 * i)):(column(4 + 3 * i)):xtic(1) \
     title columnheader(2 + 3 * i) lc rgb word(colours, i + 1)
