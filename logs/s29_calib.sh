source .venv/bin/activate
python -m posenet.calibrate --data data/calib_rand --data data/calib_twinlook --test data/mvor_twin:4 --test data/mvor_alt:4 --cache runs/calib_cache --threads 2 --json runs/s29_calib_a.json 2>&1 | grep -v "it/s\|frame/s" | tail -12
echo "$(date +%T) a done"
python -m posenet.calibrate --data data/calib_rand --data data/calib_twinlook --data data/seq_tune --data data/seq_t3 --data data/seq_t4 --data data/seq_t5 --data data/seq_t6 --data data/seq_t7 --data data/seq_t8 --data data/seq_t9 \
   --test data/mvor_twin:4 --test data/mvor_alt:4 --test data/seq_t10 --test data/seq_t11 --test data/seq_t12 --cache runs/calib_cache --threads 2 --json runs/s29_calib_c.json --plot runs/s29_calib_c.png 2>&1 | grep -v "it/s\|frame/s" | tail -14
echo "$(date +%T) c done"
echo CALIB_DONE
