"""PNG decoding of a served frame: the service's decoders (OpenCV, ``service.decode``) against other PNG decoders
that give the same pixels (imagecodecs' libpng, Pillow, Wuffs through pywuffs; each where it is installed).

    python benchmarks/png_decode.py --data data/mvor_altmesh4 --day 4 --index 2 [--repeats 30] [--json OUT]

For each view of one frame: milliseconds per colour and depth image (median of ``--repeats``, one thread; the
decoders are measured in turn ``--rounds`` times and each figure is the median over the rounds, since a shared
machine drifts), at the recorded size and brought to the size the networks read (``--reduce``, 2 for 640x480
against 320x240, as the service does), and the whole frame (every colour and depth image) on a pool of
``--threads`` threads, as ``service.validation`` decodes a request. Every decoded image is checked equal to the
service's, bit for bit. Prints the machine and a table; ``--json`` writes the rows.
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import json
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np
from posenet_speed import median_time
from tqdm import tqdm

from posenet.data.images import subsample_color, subsample_depth
from posenet.runtime.execution import machine, machine_line
from service.decode import decode_color, decode_depth


def _imagecodecs():
    import imagecodecs

    return (
        lambda d, r: subsample_color(imagecodecs.png_decode(d), r),
        lambda d, r: subsample_depth(imagecodecs.png_decode(d), r),
    )


def _wuffs():
    from pywuffs import ImageDecoderType, PixelFormat
    from pywuffs.aux import ImageDecoder, ImageDecoderConfig

    def decoder(pixel_format):
        config = ImageDecoderConfig()
        config.enabled_decoders = [ImageDecoderType.PNG]
        config.pixel_format = pixel_format
        return ImageDecoder(config)

    local = threading.local()  # a decoder per thread: the frame is decoded on a pool

    def decode(data: bytes, pixel_format) -> np.ndarray:
        decoders = local.__dict__.setdefault("decoders", {})
        if pixel_format not in decoders:
            decoders[pixel_format] = decoder(pixel_format)
        return decoders[pixel_format].decode(data).pixbuf

    def depth(data: bytes) -> np.ndarray:
        pixels = decode(data, PixelFormat.Y_16LE)  # (H, W, 2) bytes of little-endian uint16
        return pixels.view("<u2").reshape(pixels.shape[:2])

    return (
        lambda d, r: subsample_color(decode(d, PixelFormat.RGB), r),
        lambda d, r: subsample_depth(depth(d), r),
    )


def _pillow():
    from PIL import Image

    def read(data: bytes) -> np.ndarray:
        with Image.open(io.BytesIO(data)) as image:
            return np.asarray(image)

    return lambda d, r: subsample_color(read(d), r), lambda d, r: subsample_depth(read(d), r)


def decoders() -> dict:
    """name: (colour, depth) functions of (bytes, reduce), for the service and each other decoder installed."""
    found = {"service": (lambda d, r: decode_color(d, reduce=r), lambda d, r: decode_depth(d, reduce=r))}
    for name, module, make in (
        ("imagecodecs", "imagecodecs", _imagecodecs), ("pillow", "PIL", _pillow), ("wuffs", "pywuffs", _wuffs),
    ):  # fmt: skip
        if importlib.util.find_spec(module) is not None:
            found[name] = make()
    return found


def frame_files(data: Path, day: int, index: int) -> list[tuple[bytes, bytes]]:
    """(colour, depth) PNG bytes of each camera of frame ``index`` (sorted file order) of ``day``."""
    cams = sorted((data / f"day{day}").glob("cam*"))
    if not cams:
        raise SystemExit(f"no {data}/day{day}/cam*/ folders: render one with `python -m posenet.synth --out {data} "
                         f"--from-mvor MVOR.json --mvor-days {day}`")  # fmt: skip
    views = []
    for cam in cams:
        colors = sorted((cam / "color").glob("*.png"))
        if index >= len(colors):
            raise SystemExit(f"{cam}/color holds {len(colors)} PNG frames; --index {index} is beyond them")
        views.append((colors[index].read_bytes(), (cam / "depth" / colors[index].name).read_bytes()))
    return views


def median_ms(fn, repeats: int) -> float:
    return 1e3 * median_time(fn, repeats)


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, required=True, help="an MVOR-format dataset with PNG views")
    p.add_argument("--day", type=int, default=4)
    p.add_argument("--index", type=int, default=2, help="which frame of the day (sorted file order)")
    p.add_argument(
        "--reduce", type=int, default=2, help="the service's reduction (2: 640x480 read at 320x240)"
    )
    p.add_argument("--threads", type=int, default=2, help="decoding threads for the whole frame")
    p.add_argument("--repeats", type=int, default=30, help="timed runs per measurement (median)")
    p.add_argument(
        "--rounds", type=int, default=5, help="the decoders measured in turn this many times (median)"
    )
    p.add_argument("--json", type=Path, help="also write the rows here")
    args = p.parse_args(argv)
    cv2.setNumThreads(1)
    views = frame_files(args.data, args.day, args.index)
    found = decoders()
    service_color, service_depth = found["service"]
    for color, depth in views:  # the same pixels, or no figure
        for reduce in (1, args.reduce):
            want_color, want_depth = service_color(color, reduce), service_depth(depth, reduce)
            for name, (color_fn, depth_fn) in found.items():
                np.testing.assert_array_equal(color_fn(color, reduce), want_color, err_msg=name)
                np.testing.assert_array_equal(depth_fn(depth, reduce), want_depth, err_msg=name)
    info = machine()
    print(machine_line(info))
    sizes = [f"{len(c) // 1000}+{len(d) // 1000} KB" for c, d in views]
    print(f"{args.data} day {args.day} frame {args.index}: {len(views)} views (colour+depth {', '.join(sizes)}); "
          "every decoder's pixels equal the service's bit for bit")  # fmt: skip
    pool = ThreadPoolExecutor(args.threads)
    timed: dict[str, dict[str, list[float]]] = {name: {} for name in found}
    for _ in tqdm(range(args.rounds), desc="rounds", disable=args.rounds < 2):
        for name, (color_fn, depth_fn) in found.items():  # the decoders in turn, round after round
            got = timed[name]
            for reduce in (1, args.reduce):
                for kind, fn, index in (("color", color_fn, 0), ("depth", depth_fn, 1)):
                    per_view = [
                        median_ms(lambda f=fn, b=v[index], r=reduce: f(b, r), args.repeats) for v in views
                    ]
                    got.setdefault(f"{kind}_ms_r{reduce}", []).append(float(np.mean(per_view)))

            def whole(color_fn=color_fn, depth_fn=depth_fn):
                jobs = [pool.submit(color_fn, c, args.reduce) for c, _ in views]
                jobs += [pool.submit(depth_fn, d, args.reduce) for _, d in views]
                for job in jobs:
                    job.result()

            got.setdefault(f"frame_ms_{args.threads}threads", []).append(median_ms(whole, args.repeats))
    rows = [
        {"decoder": name, **{k: float(np.median(v)) for k, v in got.items()}} for name, got in timed.items()
    ]
    pool.shutdown()
    r = args.reduce
    print(
        f"{'decoder':<13}{'colour ms':>11}{f'/{r}':>8}{'depth ms':>11}{f'/{r}':>8}{f'frame, {args.threads} thr':>15}"
    )
    for row in rows:
        print(f"{row['decoder']:<13}{row['color_ms_r1']:>11.2f}{row[f'color_ms_r{r}']:>8.2f}{row['depth_ms_r1']:>11.2f}"
              f"{row[f'depth_ms_r{r}']:>8.2f}{row[f'frame_ms_{args.threads}threads']:>15.2f}")  # fmt: skip
    print(
        f"(per image: the mean over the views of each one's median; frame: all {2 * len(views)} images at /{r})"
    )
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "data": str(args.data), "rows": rows}, indent=1))
    return rows


if __name__ == "__main__":
    main()
