"""Hardware-in-the-loop: spiral design math, the MuJoCo plant, the virtual board and the scenario harness."""
