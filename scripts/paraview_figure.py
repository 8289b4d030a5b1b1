"""Renders one time step of a reprocessed run's series.pvd as a ParaView figure (pvbatch, Debian's paraview
and python3-paraview): a z slice coloured by vorticity z on a diverging map centred on zero, with arrows
of the in-plane velocity at the valid nodes, axes in mm, a labelled colour bar.

    pvbatch scripts/paraview_figure.py RUN/reprocessed/series.pvd -o figure.png [--step N]
    (without a display: scripts/paraview_figure.sh, which runs it under Xvfb)
"""
import argparse
import os
import sys

from paraview import simple as pv


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("series", help="series.pvd written by `plenopiv process --run`")
    p.add_argument("-o", "--output", required=True, help="PNG to write")
    p.add_argument("--step", type=int, default=0, help="time step (pair in time order), default the first")
    args = p.parse_args()
    if not os.path.isfile(args.series):
        sys.exit("paraview_figure: %s: no such file" % args.series)

    reader = pv.PVDReader(FileName=os.path.abspath(args.series))
    reader.UpdatePipelineInformation()
    times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
    if not 0 <= args.step < len(times):
        sys.exit("paraview_figure: %s has %d time steps, no step %d" % (args.series, len(times), args.step))
    time = times[args.step]
    reader.UpdatePipeline(time)
    info = reader.GetDataInformation()
    x0, x1, y0, y1, z0, z1 = info.GetBounds()
    for name in ("velocity_m_s", "vorticity_1_s_vec", "valid"):
        if reader.PointData.GetArray(name) is None:
            sys.exit("paraview_figure: %s has no point array %s (arrays: %s)"
                     % (args.series, name, ", ".join(reader.PointData.keys())))

    view = pv.CreateView("RenderView")
    view.ViewSize = [1100, 900]
    view.ViewTime = time
    view.UseColorPaletteForBackground = 0
    view.Background = [1, 1, 1]
    view.OrientationAxesVisibility = 0

    # The slice through the middle of the box, normal to z (the optical axis).
    cut = pv.Slice(Input=reader)
    cut.SliceType = "Plane"
    cut.SliceType.Origin = [(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2]
    cut.SliceType.Normal = [0, 0, 1]
    shown = pv.Show(cut, view)
    pv.ColorBy(shown, ("POINTS", "vorticity_1_s_vec", "Z"))
    lut = pv.GetColorTransferFunction("vorticity_1_s_vec")
    lut.ApplyPreset("Cool to Warm", True)
    lut.VectorMode = "Component"
    lut.VectorComponent = 2
    vorticity_z = cut.PointData["vorticity_1_s_vec"].GetRange(2)
    limit = max(abs(vorticity_z[0]), abs(vorticity_z[1])) or 1.0
    lut.RescaleTransferFunction(-limit, limit)  # diverging, centred on zero
    bar = pv.GetScalarBar(lut, view)
    bar.Title = "vorticity z (1/s)"
    bar.ComponentTitle = ""
    bar.TitleColor = bar.LabelColor = [0, 0, 0]
    bar.WindowLocation = "Any Location"
    bar.Position = [0.86, 0.15]
    bar.RangeLabelFormat = "%-#.0f"
    bar.ScalarBarLength = 0.7
    bar.Visibility = 1

    # Arrows of the velocity at the nodes that hold a vector (valid = 1), drawn just above the slice.
    valid = pv.Threshold(Input=cut)
    valid.Scalars = ["POINTS", "valid"]
    valid.LowerThreshold = 0.5
    valid.UpperThreshold = 1.5
    arrows = pv.Glyph(Input=valid, GlyphType="Arrow")
    arrows.OrientationArray = ["POINTS", "velocity_m_s"]
    arrows.ScaleArray = ["POINTS", "velocity_m_s"]
    speed = valid.PointData["velocity_m_s"].GetRange(-1)[1] if valid.PointData.GetArray("velocity_m_s") else 0
    spacing = (x1 - x0) / max(1, reader.GetDataInformation().GetExtent()[1])
    arrows.ScaleFactor = 0.7 * spacing / speed if speed > 0 else 1.0  # the fastest arrow: 0.7 node spacings
    arrows.GlyphMode = "All Points"
    glyphs = pv.Show(arrows, view)
    glyphs.ColorArrayName = ["POINTS", ""]  # solid colour
    glyphs.AmbientColor = glyphs.DiffuseColor = [0, 0, 0]

    view.AxesGrid.Visibility = 1
    view.AxesGrid.XTitle, view.AxesGrid.YTitle, view.AxesGrid.ZTitle = "x (mm)", "y (mm)", "z (mm)"
    for axis in ("X", "Y", "Z"):
        setattr(view.AxesGrid, axis + "TitleColor", [0, 0, 0])
        setattr(view.AxesGrid, axis + "LabelColor", [0, 0, 0])
    view.AxesGrid.GridColor = [0.3, 0.3, 0.3]

    # Looking along +z (away from the camera, as it sees the flow), y down as the upright image shows it.
    cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2
    view.CameraPosition = [cx, cy, cz - 10 * max(x1 - x0, y1 - y0)]
    view.CameraFocalPoint = [cx, cy, cz]
    view.CameraViewUp = [0, -1, 0]
    view.CameraParallelProjection = 1
    view.ResetCamera()
    view.CameraParallelScale = 0.7 * max(x1 - x0, y1 - y0)

    pv.SaveScreenshot(args.output, view, ImageResolution=[1100, 900])
    print("paraview_figure: wrote %s (time step %d of %d, t = %g s, slice z = %.3f mm)"
          % (os.path.abspath(args.output), args.step, len(times), time, cz))


if __name__ == "__main__":
    main()
