"""Lidar + camera global localization ("Global Localization of a Mobile Robot Using Lidar and Visual
Features"): Gist keyframe retrieval, clustering, ORB + PnP, Scan2Map and a relocalization trigger over
the MCL of irmcl_warp.mcl. See run.py for the experiment."""
