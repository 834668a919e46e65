#!/usr/bin/env python3
"""Rewrite a simulated set (scripts/sim_frames.py, FITS) in another image format, through
encoders that are not gpustar's or the `png` crate's: the formats archives hold.

    python3 scripts/convert_set.py SRC DST --to png8|png16|jpeg|tiff16 [--encoder pil|opencv]
        [--quality 90]

SRC holds frame_NNNN.fits, camera.toml and truth.jsonl (scripts/sim_frames.py --format fits);
DST gets frame_NNNN.png (or .jpg) and copies of camera.toml and truth.jsonl, so that the
benchmarks score the new set against the same truth.

- png16: the 16-bit values unchanged, written by PIL (zlib, its own filter choice) or OpenCV
  (libpng, its default compression level and adaptive filters).
- png8 and jpeg: 8 bits, as a star-tracker camera with an 8-bit output would give them. Each
  frame is mapped linearly so that its sky (median) sits at 12 counts and its noise (1.4826 x the
  median absolute deviation) is 2.5 counts; stars saturate at 255. jpeg is written by PIL
  (libjpeg) at --quality (default 90), greyscale, no chroma.
- tiff16: the 16-bit values unchanged, uncompressed, by PIL (or OpenCV: LZW).

Needs numpy, astropy, pillow; opencv-python-headless for --encoder opencv.
"""
import argparse
import json
import shutil
from pathlib import Path

import numpy as np
from astropy.io import fits


def to_8bit(img):
    img = img.astype(np.float64)
    med = np.median(img)
    sigma = 1.4826 * np.median(np.abs(img - med))
    gain = 2.5 / max(sigma, 1e-9)
    return np.clip(np.rint(12.0 + (img - med) * gain), 0, 255).astype(np.uint8)


def write(img, path, fmt, encoder, quality):
    if encoder == "opencv":
        import cv2

        params = [cv2.IMWRITE_JPEG_QUALITY, quality] if fmt == "jpeg" else []
        if not cv2.imwrite(str(path), img, params):
            raise SystemExit(f"opencv could not write {path}")
        return
    from PIL import Image

    if fmt in ("png16", "tiff16"):
        Image.fromarray(img.astype(np.uint16)).save(path)
    elif fmt == "png8":
        Image.fromarray(img).save(path)
    else:
        Image.fromarray(img).save(path, quality=quality)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("src")
    ap.add_argument("dst")
    ap.add_argument("--to", required=True, choices=("png8", "png16", "jpeg", "tiff16"))
    ap.add_argument("--encoder", default="pil", choices=("pil", "opencv"))
    ap.add_argument("--quality", type=int, default=90)
    a = ap.parse_args()
    src, dst = Path(a.src), Path(a.dst)
    dst.mkdir(parents=True, exist_ok=True)
    ext = {"jpeg": ".jpg", "tiff16": ".tif"}.get(a.to, ".png")
    frames = sorted(src.glob("*.fits"))
    if not frames:
        raise SystemExit(f"no .fits frames in {src}")
    for f in frames:
        with fits.open(f) as h:
            img = np.asarray(h[0].data)
        # FITS from sim_frames.py: row 0 is the top row, as in PNG; keep the order.
        img = img.astype(np.int64)
        out = np.clip(img, 0, 65535).astype(np.uint16) if a.to in ("png16", "tiff16") else to_8bit(img)
        write(out, dst / (f.stem + ext), a.to, a.encoder, a.quality)
    for name in ("camera.toml", "truth.jsonl", "camera_true.toml"):
        if (src / name).exists():
            shutil.copy(src / name, dst / name)
    # truth.jsonl names each frame's file: the new one's name.
    t = dst / "truth.jsonl"
    rows = [json.loads(line) for line in t.read_text().splitlines() if line.strip()]
    for row in rows:
        row["file"] = str(Path(row["file"]).with_suffix(ext))
    t.write_text("".join(json.dumps(row) + "\n" for row in rows))
    print(f"{len(frames)} frames -> {dst} ({a.to}, {a.encoder})")


if __name__ == "__main__":
    main()
