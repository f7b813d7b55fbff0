"""Prints and records a side-by-side benchmark's result: arld's and Stable-Baselines3's speeds by wall clock
and by CPU time, and their ratios (argv: arld steps/s, SB3 steps/s, arld CPU s, SB3 CPU s, steps, JSON path)."""
import json, os, sys
arld, sb3, arld_cpu, sb3_cpu = map(float, sys.argv[1:5])
steps, path = int(sys.argv[5]), sys.argv[6]
load = os.getloadavg()[0]
print(f"wall clock: arld {arld:,.0f} steps/s, Stable-Baselines3 {sb3:,.0f} steps/s: {arld / sb3:.1f}x")
print(f"CPU time:   arld {steps / arld_cpu:,.0f} steps/s, Stable-Baselines3 {steps / sb3_cpu:,.0f} steps/s: "
      f"{sb3_cpu / arld_cpu:.1f}x")
print(f"({steps} steps each, load average {load:.2f} on {os.cpu_count()} cores)")
json.dump({"steps": steps, "arld_steps_per_s": arld, "sb3_steps_per_s": sb3, "ratio": arld / sb3,
           "arld_cpu_s": arld_cpu, "sb3_cpu_s": sb3_cpu, "cpu_ratio": sb3_cpu / arld_cpu,
           "load_average": load}, open(path, "w"), indent=2)
