# The held press's relaxation (viscoelastic_bench --hold-csv): gnuplot -c hold_relaxation.gp CSV PNG
set terminal png size 1000,560
set termoption noenhanced
set output ARG2
set datafile separator ","
set title "Held press on the bundled brain (4 mm in over 1.5 s, held 10 s, 1 kHz steps): the viscoelastic brain relaxes"
set xlabel "time (s)"; set ylabel "|F| on the tool (N)"; set y2label "tool tip depth (mm)"
set ytics nomirror; set y2tics
set key outside bottom center horizontal
set arrow from 1.5, graph 0 to 1.5, graph 1 nohead dt 3
set label "hold" at 1.6, graph 0.95
plot ARG1 every ::1 using 1:3 with lines lw 2 title "elastic brain (brain_artery.scene)", \
     "" every ::1 using 1:4 with lines lw 2 title "viscoelastic brain (brain_viscoelastic.scene)", \
     "" every ::1 using 1:5 with lines dt 2 lw 2 title "int g(t-s) dF_el(s): the stated model from the elastic forces", \
     "" every ::1 using 1:($2*1000) axes x1y2 with lines dt 3 title "depth (mm)"
