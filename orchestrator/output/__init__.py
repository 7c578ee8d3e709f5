"""What a run leaves: the recording and its file formats, the metrics, the figures (drawn in
worker processes while a run writes), the timeline events, the MCAP export and the 3-D view."""
