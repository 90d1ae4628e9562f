"""Regenerate the README gallery: ``python docs/gallery/make_gallery.py [--overwrite]``.

Runs the examples at full size into a temporary folder and keeps a few pictures,
reduced to a 256-colour palette so that each PNG stays under 100 KB.
"""

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
PICKS = {
    "sphere_operators": ["sphere_laplacian_cspm.png", "sphere_laplacian_boxplot.png"],
    "sausage_neighbourhood": ["sausage_neighbourhood.png"],
    "sausage_outliers": ["sausage_error_full_vs_robust.png"],
    "torus_laplacians": ["double_torus_laplacian_msph.png"],
    "heat_sphere": ["heat_sphere_final.png"],
    "area_elements": ["area_elements_histogram.png"],
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--overwrite", action="store_true")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for example, files in PICKS.items():
            subprocess.run([sys.executable, str(ROOT / "examples" / f"{example}.py"), "--out", tmp], check=True)
            for name in files:
                target = HERE / name
                if target.exists() and not args.overwrite:
                    print(f"keeping {target} (pass --overwrite to replace)")
                    continue
                img = Image.open(Path(tmp) / name).convert("RGB").quantize(colors=256, dither=Image.Dither.NONE)
                img.save(target, optimize=True)
                print(f"wrote {target} ({target.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
