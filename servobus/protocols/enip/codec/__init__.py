"""The EtherNet/IP codec: pure bytes <-> frozen dataclasses, no I/O, shared by the host
(client, scanner, discover) and the device side (device, server, connections).

``encap`` the encapsulation header (CIP Vol. 2 ch. 2), ``cpf`` the Common Packet Format,
``cip`` Message Router requests/responses, ``epath`` padded EPATHs, ``identity`` the
Identity object's attributes, ``discovery`` ListIdentity/ListServices reply items,
``connection_manager`` Forward_Open/Forward_Close/Unconnected_Send service data, ``io`` the
DYN5 Class 1 images and frames.
"""
