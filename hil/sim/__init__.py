"""The simulated arm: design math, the MuJoCo model and plant, its drives and objects. Knows no harness."""
