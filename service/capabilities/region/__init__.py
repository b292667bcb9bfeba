"""The region every mesh route starts from: its params (:mod:`.params`), their resolution into
the faces, the chart and the frame, flattened (:mod:`.resolve`), the answers they share
(:mod:`.answers`) and the region's GLB and pictures (:mod:`.pictures`)."""
