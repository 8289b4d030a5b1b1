"""plenopivd's published messages (proto/plenopiv.proto) decoded: a `vectors` message as an xarray Dataset laid
out as plenopiv.open gives a vector file."""
import numpy as np
import xarray as xr
from google.protobuf.descriptor import FieldDescriptor

from . import plenopiv_pb2

def sigma_long_name(component, method):
    """A sigma payload's long_name, as its vector file gives it: what it is and its method (the header's
    sigma_method; a daemon that does not send one: the statistic's name alone)."""
    return ("standard uncertainty of %s (%s); NaN: no estimate (invalid or interpolated)"
            % (component, method or "correlation statistics, Wieneke 2015"))


# Units and meaning of the arrays plenopivd may publish, as its vector files give them (`units`,
# `long_name`); the message carries names only, and for sigma the header's sigma_method.
PAYLOAD_ATTRIBUTES = {
    "u": ("m/s", "velocity along x"),
    "v": ("m/s", "velocity along y"),
    "w": ("m/s", "velocity along z"),
    "valid": ("1", "1: a vector (measured, or replaced by validation); 0: none"),
    "dx": ("mm", "displacement along x between the pulses"),
    "dy": ("mm", "displacement along y between the pulses"),
    "dz": ("mm", "displacement along z between the pulses"),
    "vorticity_x": ("1/s", ""),
    "vorticity_y": ("1/s", ""),
    "vorticity_z": ("1/s", ""),
    "sigma_u": ("m/s", sigma_long_name("u", "")),
    "sigma_v": ("m/s", sigma_long_name("v", "")),
    "sigma_w": ("m/s", sigma_long_name("w", "")),
}


class MessageError(ValueError):
    """A message that is not a well-formed `vectors` message; the text says what is wrong."""


def header_entries(header):
    """Every scalar field of a VectorFieldHeader by its .proto name (repeated ones left out): what the
    live subscriber keeps as a saved file's provenance, whatever fields the .proto gains."""
    return {field.name: getattr(header, field.name) for field in header.DESCRIPTOR.fields
            if field.label != FieldDescriptor.LABEL_REPEATED}


def decode_vectors(frames):
    """frames: [b"vectors", VectorFieldHeader, one little-endian float32 array per payload name]. Returns
    the field as a Dataset: each payload on (z, y, x) with units, coordinates x, y, z (mm), attributes
    dt_s, origin_mm, spacing_mm and the header's scalar fields (header_<name>)."""
    if len(frames) < 2 or frames[0] != b"vectors":
        raise MessageError("not a vectors message (topic %r)" % (frames[0][:32] if frames else b""))
    header = plenopiv_pb2.VectorFieldHeader()
    try:
        header.ParseFromString(frames[1])
    except Exception as e:  # protobuf's DecodeError has no stable import path across versions
        raise MessageError("the header is not a VectorFieldHeader (%s)" % e) from None
    if len(header.shape) != 3 or len(header.origin_mm) != 3 or len(header.spacing_mm) != 3:
        raise MessageError("the header's shape, origin_mm and spacing_mm need 3 values each, got %d, %d, %d"
                           % (len(header.shape), len(header.origin_mm), len(header.spacing_mm)))
    nx, ny, nz = header.shape
    if len(frames) - 2 != len(header.payloads):
        raise MessageError("the header names %d payloads, the message has %d" % (len(header.payloads), len(frames) - 2))
    coords = {a: (a, header.origin_mm[i] + header.spacing_mm[i] * np.arange(n), {"units": "mm"})
              for i, (a, n) in enumerate(zip("xyz", (nx, ny, nz)))}
    data_vars = {}
    for name, data in zip(header.payloads, frames[2:]):
        values = np.frombuffer(data, dtype="<f4")
        if values.size != nx * ny * nz:
            raise MessageError("payload %s has %d values, shape (nx, ny, nz) = %s needs %d"
                               % (name, values.size, (nx, ny, nz), nx * ny * nz))
        units, meaning = PAYLOAD_ATTRIBUTES.get(name, ("unknown (not in the published header)", ""))
        if name.startswith("sigma_") and header.sigma_method:
            meaning = sigma_long_name(name[len("sigma_"):], header.sigma_method)
        attrs = {"units": units}
        if meaning:
            attrs["long_name"] = meaning
        data_vars[name] = (("z", "y", "x"), values.reshape(nz, ny, nx), attrs)
    attrs = {"dt_s": header.dt_s, "origin_mm": np.array(header.origin_mm), "spacing_mm": np.array(header.spacing_mm),
             "kind": "vectors"}
    attrs.update({"header_" + k: v for k, v in header_entries(header).items()})
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)
