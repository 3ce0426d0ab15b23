# Shared look of every plot (loaded by the others): PNG at GitHub's page
# width, a clear font, light grid. Variables from generate.py: datadir, out.
set terminal pngcairo size 1000,480 font 'sans,11' noenhanced
set output out
set style fill solid 0.85 border -1
set grid ytics lc rgb '#dddddd'
set border 3
set tics nomirror
