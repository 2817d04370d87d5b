"""The experiment configs (Hydra). A package so that Hydra finds them as pkg://irmcl_warp.conf, in the checkout
(irmcl_warp/conf links here) and in an installed wheel alike."""
