"""Derives mitutoyo_R.31windows.profile_y_mm_x_mm_z_um.csv from mitutoyo_surftest_R.x_mm_z_um.csv.

31 overlapping windows of 1067 points (1.5 um pitch, 1.599 mm) whose starts advance by 186
points (0.279 mm); window i is profile i at y = 0.01 * i mm; x restarts at 0 in every window;
heights are copied unchanged. Run: python3 make_windows.py (no dependencies).
"""

WINDOW, STRIDE, COUNT, Y_STEP_MM, PITCH_MM = 1067, 186, 31, 0.01, 0.0015

rows = [line.split(",") for line in open("mitutoyo_surftest_R.x_mm_z_um.csv").read().split()[1:]]
z = [r[1] for r in rows]
assert (COUNT - 1) * STRIDE + WINDOW <= len(z)
with open("mitutoyo_R.31windows.profile_y_mm_x_mm_z_um.csv", "w") as out:
    out.write("profile,y_mm,x_mm,z_um\n")
    for i in range(COUNT):
        for j in range(WINDOW):
            out.write(f"{i},{i * Y_STEP_MM:.2f},{j * PITCH_MM:.4f},{z[i * STRIDE + j]}\n")
