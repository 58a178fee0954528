"""The demos of the sparse-sensor methods (``wearpose demo --kit imu6|mimu6|miposer``): a held-out
clip -> simulated sensors -> the method's estimate -> metrics and a page beside the ground truth,
plus the figures they draw. They sit above the estimators and the viewer because they use both;
each module is named by its method's declaration (``MethodSpec.demos``) and imported on demand
(``wearpose.cli.demo.kit_demo``), none at package import.
"""
