"""PNG decoding of image products: damaged streams are refused before libpng/OpenCV see (and print about) them."""

import struct
import zlib

import numpy as np
import pytest

from scipctl.io.images import decode_png, encode_png, png_size
from scipctl.model import InputError

GREY = np.random.default_rng(3).integers(0, 256, size=(48, 64), dtype=np.uint8)
PNG = encode_png(GREY)
IDAT = PNG.index(b"IDAT")


def _damaged(how: str) -> bytes:
    b = bytearray(PNG)
    if how == "idat-bit":  # libpng: "IDAT: incorrect data check" / "bad adaptive filter value" on stderr
        b[IDAT + 40] ^= 0x10
    elif how == "truncated":  # OpenCV: "[ WARN...] PNG input buffer is incomplete" on stderr
        return bytes(b[: len(b) - 30])
    elif how == "idat-duplicated-range":
        b[IDAT + 30:IDAT + 30] = b[IDAT + 30:IDAT + 60]
    elif how == "iend-crc":  # libpng: "IEND: CRC error"
        b[-1] ^= 0x01
    elif how == "chunk-type":  # OpenCV: "IHDR chunk shall be first" (the CRC made to match)
        b[12] = ord("J")
        b[29:33] = struct.pack(">I", zlib.crc32(bytes(b[12:29])))
    elif how == "no-idat":
        end = IDAT - 4 + 12 + struct.unpack(">I", PNG[IDAT - 4:IDAT])[0]
        del b[IDAT - 4:end]
    return bytes(b)


@pytest.mark.parametrize("how, fragment", [
    ("idat-bit", "IDAT chunk at byte 33 fails its CRC"),
    ("truncated", "truncated: IDAT chunk at byte 33 runs past the end"),
    ("idat-duplicated-range", "IDAT chunk at byte 33 fails its CRC"),
    ("iend-crc", "IEND chunk"),
    ("chunk-type", "starts with a JHDR chunk, not IHDR"),
    ("no-idat", "no IDAT chunk"),
])
def test_damaged_png_is_an_input_error_and_nothing_is_printed(capfd, how, fragment):
    with pytest.raises(InputError) as ei:
        decode_png(_damaged(how), "navcam_left_1_0")
    e = ei.value
    assert (e.product, e.field) == ("navcam_left_1_0", "image")
    assert e.message.startswith("corrupt PNG") and fragment in e.message, e.message
    assert capfd.readouterr() == ("", "")  # before the check, libpng/OpenCV printed a line of their own


def test_png_size_reads_the_header_of_valid_pngs():
    assert png_size(PNG, "p") == (64, 48)
    assert png_size(encode_png(GREY.astype(np.uint16) * 257), "p") == (64, 48)
    assert png_size(PNG + b"trailing bytes after IEND are ignored", "p") == (64, 48)
    np.testing.assert_array_equal(decode_png(PNG, "p"), GREY)


def test_png_size_trusts_a_header_whose_crc_matches():
    b = bytearray(PNG)
    b[16:24] = struct.pack(">II", 20000, 20000)
    b[29:33] = struct.pack(">I", zlib.crc32(bytes(b[12:29])))
    assert png_size(bytes(b), "p") == (20000, 20000)  # (validate compares it with width x height before decoding)


@pytest.mark.parametrize("data", [b"", b"GIF89a....", "a string"], ids=["empty", "gif", "str"])
def test_not_png_data(data):
    with pytest.raises(InputError, match="not PNG data"):
        png_size(data, "p")


def _grey_png(bit_depth: int, rows: list) -> bytes:
    """A greyscale PNG of ``bit_depth`` built by hand (OpenCV writes only 8 and 16 bits); rows of packed bytes."""
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))

    width = len(rows[0]) * 8 // bit_depth
    raw = b"".join(b"\x00" + bytes(r) for r in rows)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, len(rows), bit_depth, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


@pytest.mark.parametrize("bit_depth", [1, 2, 4])
def test_low_bit_depth_greyscale_is_refused(bit_depth):
    """The contract's image is 'PNG, single channel, 8- or 16-bit'. A 1/2/4-bit greyscale PNG was decoded by
    OpenCV into 8-bit samples scaled to 0-255 and accepted as if it were an 8-bit image."""
    data = _grey_png(bit_depth, [[0x5A, 0xC3]] * 4)
    assert png_size(data, "p") == (16 // bit_depth, 4)
    with pytest.raises(InputError) as ei:
        decode_png(data, "p")
    assert (ei.value.product, ei.value.field) == ("p", "image") and f"{bit_depth}-bit" in ei.value.message


def test_hand_built_8_bit_greyscale_is_read():
    assert decode_png(_grey_png(8, [[1, 2, 3]] * 2), "p").tolist() == [[1, 2, 3]] * 2
