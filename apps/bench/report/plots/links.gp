# CAN and serial goodput against their physical limits: per case the share
# of the limit (median of repetitions, whiskers min..max) and the target.
# Variables: datadir, out, ncan, nserial; datadir/can.dat, serial.dat.
load sprintf('%s/common.gp', system('dirname "' . ARG0 . '"'))
set terminal pngcairo size 1000,480 font 'sans,11' noenhanced
set output out
set multiplot layout 1,2 title "Links against their limits, measured in the same run (median, whiskers min..max)" font 'sans,13'
set style data histograms
set style histogram errorbars gap 2 lw 1
set boxwidth 0.9
set yrange [0:124]
set ytics 0,20,100
set key top right font 'sans,10'
set xtics rotate by -25 font 'sans,10'
if (ncan > 0) {
  set title 'CAN, emulated 1 Mbit/s bus'
  set ylabel '% of the 8-byte data field / of bus time'
  set arrow 1 from graph 0, first 87 to graph 1, first 87 nohead dt 2 lw 2 lc rgb '#c00000'
  set label 1 '- - target: payload ≥ 87 %' at graph 0.02, graph 0.96 tc rgb '#c00000' font 'sans,10' front
  set xrange [-0.6:ncan - 0.4]
  plot datadir.'/can.dat' skip 1 using ($2*100):($3*100):($4*100):xtic(1) title 'payload efficiency' lc rgb '#1f77b4', \
       '' skip 1 using ($5*100):($6*100):($7*100) title 'bus load' lc rgb '#aec7e8'
  unset arrow 1
  unset label 1
}
if (nserial > 0) {
  set title 'Serial, 19,200 baud 8N1, MTU 32'
  set ylabel '% of the line rate (1,920 B/s) / of line time'
  set arrow 2 from graph 0, first 80 to graph 1, first 80 nohead dt 2 lw 2 lc rgb '#c00000'
  set label 2 '- - target: goodput ≥ 80 %' at graph 0.02, graph 0.96 tc rgb '#c00000' font 'sans,10' front
  set xrange [-0.6:nserial - 0.4]
  plot datadir.'/serial.dat' skip 1 using ($2*100):($3*100):($4*100):xtic(1) title 'goodput' lc rgb '#2ca02c', \
       '' skip 1 using ($5*100):($6*100):($7*100) title 'line busy' lc rgb '#98df8a'
}
unset multiplot
